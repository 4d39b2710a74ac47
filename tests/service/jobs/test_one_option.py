"""One option, one place: a row added to the options table reaches every front door.

The test copies the source into a temporary folder, adds one throwaway option to the copy's
:data:`loceval.options.OPTIONS` (a textual edit of that one table, nothing else), and finds
the option, with its bounds and help, in ``loceval evaluate --help``, in ``/openapi.json``
and ``GET /api/v1/options``, in the validation of ``POST /evaluations`` and of a stored
request, and as a field of the browser page's form (real Chromium), with no other edit.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from tests.service.api.test_web_browser import browser, page

__all__ = ["browser", "page"]  # the fixtures, used by name

pytestmark = [pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[3]

# The throwaway option: a number with an exclusive minimum, a maximum and a default.
_ROW = """    OptionSpec(
        "throwaway_m",
        OptionKind.NUMBER,
        0.25,
        "a throwaway distance that only this test knows, metres",
        "the throwaway distance",
        "throwaway",
        "M",
        minimum=0.0,
        maximum=7.5,
        exclusive_minimum=True,
    ),
"""
_TABLE_END = ')\n"""Every option, in the order ``--help`` and the API schema list them."""'

# Run inside the copy: the app's schema, its options document, its page and script, and the
# validation of a new request and of a stored one, printed as one JSON document.
_PROBE = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path

    import loceval.options
    from pydantic import ValidationError
    from service.schemas.evaluations import EvaluationCreate
    from tests.service._api_fixtures import open_api

    out = {"table": loceval.options.__file__}
    with open_api(Path(sys.argv[1])) as api:
        schema = api.client.get("/openapi.json").json()
        out["schema"] = schema["components"]["schemas"]["EvaluationOptions"]["properties"][
            "throwaway_m"
        ]
        listed = api.client.get("/api/v1/options", headers=api.headers).json()["items"]
        out["document"] = [item for item in listed if item["key"] == "throwaway_m"]
        body = {"reference": {"dataset_id": "ds_x"}, "estimates": [{"dataset_id": "ds_y"}]}
        refused = api.client.post(
            "/api/v1/evaluations",
            json={**body, "options": {"throwaway_m": 9}},
            headers=api.headers,
        )
        out["refused"] = {"status": refused.status_code, "body": refused.json()}
        out["page"] = api.client.get("/").text
        out["script"] = api.client.get("/web/app.js").text
        out["style"] = api.client.get("/web/app.css").text
    stored = {**body, "options": {"throwaway_m": 1.5}}
    out["stored"] = EvaluationCreate.model_validate(stored).options.throwaway_m
    try:
        EvaluationCreate.model_validate({**body, "options": {"throwaway_m": 0}})
    except ValidationError as err:
        out["stored_refused"] = [list(e["loc"]) for e in err.errors()]
    print(json.dumps(out))
    """
)


@pytest.fixture(scope="module")
def copy_with_option(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the source whose options table has one more row (and no other change)."""
    root = tmp_path_factory.mktemp("one-option")
    for name in ("loceval", "exporters", "service", "templates", "tests"):
        shutil.copytree(
            ROOT / name, root / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc")
        )
    table = root / "loceval" / "options.py"
    text = table.read_text(encoding="utf-8")
    assert text.count(_TABLE_END) == 1, "the options table's end moved; update _TABLE_END"
    table.write_text(text.replace(_TABLE_END, _ROW + _TABLE_END), encoding="utf-8")
    return root


def _run(root: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """Run Python in the copy: its folder first on the path, before the installed checkout."""
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.run(
        [sys.executable, *args],
        check=False,
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def probe(copy_with_option: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """What the copy's API, page and stored-request validation say of the new option."""
    done = _run(copy_with_option, "-c", _PROBE, str(tmp_path_factory.mktemp("api")))
    assert done.returncode == 0, done.stderr
    found: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    assert Path(found["table"]).is_relative_to(copy_with_option)  # the copy's table ran
    return found


def test_the_cli_offers_it(copy_with_option: Path) -> None:
    """``loceval evaluate --help`` lists ``--throwaway M`` with its help and default."""
    done = _run(copy_with_option, "-m", "service.cli", "evaluate", "--help")
    assert done.returncode == 0, done.stderr
    text = " ".join(done.stdout.split())
    assert "--throwaway M" in text
    assert "a throwaway distance that only this test knows, metres" in text
    assert "0.25" in text
    refused = _run(copy_with_option, "-m", "service.cli", "evaluate", "a", "b", "--throwaway", "x")
    assert refused.returncode == 1
    assert "--throwaway" in refused.stderr


def test_the_api_schema_and_options_document_have_it(probe: dict[str, Any]) -> None:
    """The OpenAPI property and ``GET /api/v1/options`` carry its bounds, default and help."""
    schema = probe["schema"]
    assert schema["type"] == "number"
    assert schema["exclusiveMinimum"] == 0.0
    assert schema["maximum"] == 7.5
    assert schema["default"] == 0.25
    assert schema["description"] == "a throwaway distance that only this test knows, metres"
    (row,) = probe["document"]
    assert row["kind"] == "number"
    assert row["flag"] == "--throwaway"
    assert row["bounds"] == "more than 0 and at most 7.5"


def test_requests_new_and_stored_are_checked_against_it(probe: dict[str, Any]) -> None:
    """A new request out of bounds gets a 422 naming it; a stored request is read with it."""
    assert probe["refused"]["status"] == 422
    assert ["body", "options", "throwaway_m"] in [
        e["loc"] for e in probe["refused"]["body"]["errors"]
    ]
    assert probe["stored"] == 1.5
    assert probe["stored_refused"] == [["options", "throwaway_m"]]


def test_the_page_makes_a_field_for_it(page: Any, probe: dict[str, Any]) -> None:
    """The form has a field for it, with its words, help, bounds and default, and checks it."""
    from playwright.sync_api import expect

    files = {
        "/": (probe["page"], "text/html"),
        "/web/app.js": (probe["script"], "text/javascript"),
        "/web/app.css": (probe["style"], "text/css"),
    }

    def serve(route: Any) -> None:
        path = "/" + route.request.url.split("://", 1)[1].split("/", 1)[1].split("?")[0]
        if path not in files:
            route.fulfill(status=404, body="")
            return
        body, media_type = files[path]
        route.fulfill(status=200, body=body, content_type=media_type)

    page.route("http://loceval.test/**", serve)
    page.goto("http://loceval.test/")
    field = page.locator("#other-options-grid [data-option='throwaway_m']")
    expect(field).to_have_count(1)
    expect(field).to_have_attribute(
        "title", "a throwaway distance that only this test knows, metres"
    )
    expect(field).to_contain_text("Throwaway distance")  # its words, without "the"
    expect(field).to_contain_text("more than 0 and at most 7.5")
    number = field.locator("input[type=number]")
    expect(number).to_have_attribute("max", "7.5")
    expect(number).to_have_attribute("placeholder", "0.25")
    expect(number).to_have_attribute("min", "0")
    assert field.evaluate("f => f.closest('form').id") == "eval-form"
