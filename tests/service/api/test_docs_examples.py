"""The API schema's examples are real answers, and its answers are all documented (issue 44).

``/docs`` shows what ``/openapi.json`` documents: each status's example, or one Swagger UI
makes from the schema's ``examples``. Here every example is held to its schema (JSON Schema
2020-12, by jsonschema-rs) and to the status it is shown under, no example text looks like a
random string, and the documented examples of a few answers are compared with the answers
the service gives. The page itself is read in test_docs_browser.py.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import jsonschema_rs
import pytest

from tests.service._api_fixtures import Api

PROBLEM_JSON = "application/problem+json"
_ODD = re.compile(r"[!#$%&*;<>?@\[\\\]^`|~]")


def looks_random(text: str) -> bool:
    """Whether a text reads like a string generated from a pattern, not a person's words.

    Swagger UI fills a text that has a ``pattern`` and no example with a random match
    (``yEH*!k>S&NQdY;;``): a word of six or more characters (its sentence's punctuation at
    its ends left out), two or more and one in seven of them punctuation nobody types
    together (``0.10@95`` has one).
    """
    for word in text.split():
        kept = word.strip(".,;:()'\"")
        odd = len(_ODD.findall(kept))
        if len(kept) >= 6 and odd >= 2 and odd * 7 >= len(kept):
            return True
    return False


def test_looks_random_tells_junk_from_words() -> None:
    """The junk of the issue is random; messages, crons, selectors and URLs are not."""
    for junk in ("_e,7qi1@xitiC|v!", "yEH*!k>S&NQdY;;", "h#[x_<gmdFJeW5"):
        assert looks_random(junk), junk
    for words in (
        "0 7 * * mon",
        "0.10@95",
        "tf:map:base_link",
        "run.mcap: no topic '/odom'; the bag has /amcl_pose, /tf.",
        "https://loceval.example.org/api/v1/evaluations/297a1e94/artifacts/report.pdf",
        'loceval_http_requests_total{method="GET",route="/api/v1/datasets",status="200"} 4.0',
    ):
        assert not looks_random(words), words


@pytest.fixture
def document(api: Api) -> dict[str, Any]:
    """The service's OpenAPI document."""
    answer = api.client.get("/openapi.json")
    assert answer.status_code == 200
    openapi: dict[str, Any] = answer.json()
    return openapi


def _validate(document: dict[str, Any], schema: dict[str, Any], example: Any, where: str) -> None:
    root = {**schema, "components": document["components"]}  # "#/components/..." resolve here
    errors = [
        f"{list(e.instance_path)}: {e.message}"
        for e in jsonschema_rs.Draft202012Validator(root).iter_errors(example)
    ]
    assert errors == [], f"{where}: {errors}"


def _strings(value: Any) -> Iterator[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield str(key)
            yield from _strings(item)
    elif isinstance(value, list):
        for item in value:
            yield from _strings(item)


def _responses(document: dict[str, Any]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    for path, operations in document["paths"].items():
        for method, operation in operations.items():
            for code, response in operation["responses"].items():
                yield f"{method.upper()} {path} {code}", code, response


def test_every_example_is_an_answer_of_its_status_and_schema(document: dict[str, Any]) -> None:
    """Each response's example validates against its schema; a problem's status is its code."""
    shown = 0
    for where, code, response in _responses(document):
        for media_type, content in response.get("content", {}).items():
            if "example" not in content:
                continue
            shown += 1
            example = content["example"]
            _validate(document, content.get("schema", {}), example, f"{where} {media_type}")
            if media_type == PROBLEM_JSON:
                assert example["status"] == int(code), where
            for text in _strings(example):
                assert not looks_random(text), (where, text)
    assert shown >= 100  # every problem of every route, and the answers without a model


def test_every_problem_is_documented_as_problem_json_with_its_own_example(
    document: dict[str, Any],
) -> None:
    """No 4xx/5xx of the API shows another status's example (the 401 was the 422's)."""
    for where, code, response in _responses(document):
        if not code.startswith(("4", "5")) or where.split()[1] in {"/solve", "/readyz"}:
            continue
        if where.startswith("POST /hops/"):
            continue  # Hops' own answers, below
        content = response["content"]
        assert PROBLEM_JSON in content, where
        assert content[PROBLEM_JSON]["example"]["status"] == int(code), where


def test_the_models_examples_are_valid_and_written_by_a_person(document: dict[str, Any]) -> None:
    """Every answer's model carries an example (Swagger UI shows it, not "string"), valid."""
    schemas = document["components"]["schemas"]
    for name in (
        "DatasetPublic",
        "DatasetUploaded",
        "EvaluationPublic",
        "OptionPublic",
        "SchedulePublic",
        "ScheduleWithSecret",
        "ScheduleRunPublic",
        "ComparisonPublic",
        "HopsAnswer",
        "SourceRef",
        "ArtifactPublic",
        "SummaryRow",
    ):
        assert schemas[name].get("examples"), name
    for name, schema in schemas.items():
        for example in schema.get("examples", []):
            if not isinstance(example, dict):
                continue  # a field's examples, not a document
            _validate(document, {"$ref": f"#/components/schemas/{name}"}, example, name)
            for text in _strings(example):
                assert not looks_random(text), (name, text)
                assert text not in {"string", "additionalProp1"}, name


def test_documented_problems_are_the_answers_the_service_gives(api: Api) -> None:
    """The 401 shown is the 401 sent; so is POST /evaluate's answer without estimates."""
    document = api.client.get("/openapi.json").json()
    paths = document["paths"]

    def shown(path: str, method: str, code: str) -> dict[str, Any]:
        example: dict[str, Any] = paths[path][method]["responses"][code]["content"][PROBLEM_JSON][
            "example"
        ]
        return example

    sent = api.client.get("/api/v1/datasets").json()
    assert shown("/api/v1/datasets", "get", "401") == sent
    answer = api.client.post(
        "/api/v1/evaluate", headers=api.headers, files={"reference": ("gt.txt", b"0 0 0 0\n")}
    )
    assert answer.status_code == 400
    assert shown("/api/v1/evaluate", "post", "400") == answer.json()
    unknown = api.client.get("/hops/path")
    assert unknown.status_code == 404
    assert shown("/hops/{name}", "get", "404") == unknown.json()


def test_hops_and_the_one_shot_answers_are_documented(api: Api) -> None:
    """/hops/{name}'s 404, /solve's 422 in Hops' shape, and /evaluate's need of estimates."""
    document = api.client.get("/openapi.json").json()
    paths = document["paths"]
    assert PROBLEM_JSON in paths["/hops/{name}"]["get"]["responses"]["404"]["content"]
    for path in ("/solve", "/hops/{name}"):
        refused = paths[path]["post"]["responses"]["422"]["content"]
        hops = refused["application/json"]
        assert hops["schema"] == {"$ref": "#/components/schemas/HopsAnswer"}
        assert set(hops["example"]) == {"values", "errors", "warnings"}
        assert hops["example"]["errors"]
        assert PROBLEM_JSON in refused  # a malformed request is still a problem document
    # the answer Rhino's Hops client gets for an empty input is that shape, not a problem
    key = {"RhinoComputeKey": api.key}
    answer = api.client.post("/solve", json={"pointer": "hops/paths", "values": []}, headers=key)
    assert answer.status_code == 422
    assert answer.headers["content-type"].startswith("application/json")
    assert set(answer.json()) == {"values", "errors", "warnings"}
    _validate(document, {"$ref": "#/components/schemas/HopsAnswer"}, answer.json(), "/solve")

    body = paths["/api/v1/evaluate"]["post"]["requestBody"]["content"]["multipart/form-data"]
    schema = body["schema"]
    assert {"required": ["estimate"]} in schema["anyOf"]
    assert {"required": ["estimate_selector"]} in schema["anyOf"]
    assert "estimate_selector" in schema["description"]
    shown = paths["/api/v1/evaluate"]["post"]["responses"]["400"]["content"][PROBLEM_JSON]
    assert "estimate_selector" in shown["example"]["detail"]
