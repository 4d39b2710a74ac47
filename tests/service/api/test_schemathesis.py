"""Schema fuzzing: schemathesis against the app's own OpenAPI document, with and without a key.

The schema is read at import (``@schema.parametrize()`` needs it then) from an app built on a
placeholder runtime, which serves the same document; a test checks it equals the served one.
Requests go to the real app of the ``api`` fixture through a small ASGI proxy, because the
fixture's data folder exists only at run time (``schemathesis.pytest.from_fixture`` would
avoid the proxy, but it reads pytest's private ``Node._nodeid``, gone in pytest 9).

Multipart bodies are generated from the declared request bodies; the file parts are then
replaced, per example, by one of a few real recordings (valid TUM/CSV/MCAP, a truncated MCAP,
random bytes) or kept as generated, so uploads reach the readers rather than stopping at
"unrecognised file".
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, Iterator, MutableMapping
from typing import Any

import numpy as np
import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    allow_header_conformance,
    content_type_conformance,
    ignored_auth,
    missing_required_header,
    negative_data_rejection,
    positive_data_acceptance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
    unsupported_method,
)

from tests import bagfactory
from tests.factories import make_trajectory, perturb, write_csv, write_tum
from tests.service._api_fixtures import (
    PROBLEM_JSON,
    PROBLEM_KEYS,
    Api,
    bearer,
    offline_app,
    open_api,
)

_Scope = MutableMapping[str, Any]
_Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
_Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]

SPEC: dict[str, Any] = offline_app().openapi()

MULTIPART = frozenset({"/api/v1/datasets", "/api/v1/evaluate"})
FILE_FIELDS = {"file", "reference", "estimate"}
RECORDINGS = ("tum", "csv", "generated", "mcap", "mcap-truncated", "random")

CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    negative_data_rejection,
    positive_data_acceptance,
    missing_required_header,
    unsupported_method,
    allow_header_conformance,
    ignored_auth,
]
"""Every built-in check of single responses; the stateful ones need links the API lacks."""

EXAMPLES = 100
"""Examples per operation of the with-key run (the issue asks for at least 100, every check)."""
OTHER_EXAMPLES = 20
"""Examples per operation of the runs that check one property (no key, uploads of files)."""


class _Proxy:
    """An ASGI app that forwards requests to the app of the running test.

    Lifespan events are answered here: the real app's lifespan is run by its TestClient.
    """

    app: Callable[[_Scope, _Receive, _Send], Awaitable[None]] | None = None

    async def __call__(self, scope: _Scope, receive: _Receive, send: _Send) -> None:
        if scope["type"] == "lifespan":
            while (await receive())["type"] != "lifespan.shutdown":
                await send({"type": "lifespan.startup.complete"})
            await send({"type": "lifespan.shutdown.complete"})
            return
        assert self.app is not None, "the api fixture is not active"
        await self.app(scope, receive, send)


PROXY = _Proxy()
schema = schemathesis.openapi.from_dict(SPEC)
schema.app = PROXY
# Unknown query parameters are ignored (FastAPI's behaviour, and harmless), not refused.
schema.config.generation.update(allow_extra_parameters=False)
api_schema = schema.include(path_regex="^/api/v1/")
# A tus request without (or with another) Tus-Resumable is refused with the protocol's 412.
_rejection = schema.config.checks.negative_data_rejection
_rejection.expected_statuses = [*_rejection.expected_statuses, "412"]
_missing_header = schema.config.checks.missing_required_header
_missing_header.expected_statuses = [*_missing_header.expected_statuses, "412"]


@schemathesis.serializer("application/offset+octet-stream")
def _offset_octets(_ctx: Any, value: Any) -> bytes:
    """A resumable upload's bytes (tus): sent as they are, generated text as UTF-8."""
    return value if isinstance(value, bytes) else str(value).encode()


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Api]:
    """One app for the module's examples; the proxy points at it while the module runs."""
    with open_api(tmp_path_factory.mktemp("schemathesis")) as api:
        PROXY.app = api.app
        try:
            yield api
        finally:
            PROXY.app = None


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Real files to put into the generated multipart bodies (seeded like the rng fixture)."""
    rng = np.random.default_rng(20240601)
    folder = tmp_path_factory.mktemp("recordings")
    truth = make_trajectory(rng, 60)
    poses = bagfactory.random_poses(rng, 40, dt_ns=20_000_000)
    bag = bagfactory.write_bag(
        folder / "run",
        bagfactory.pose_records("/pose", bagfactory.POSE, poses),
        fmt="mcap",
    )
    mcap = next(bag.glob("*.mcap")).read_bytes()
    return {
        "tum": write_tum(folder / "truth.txt", truth).read_bytes(),
        "csv": write_csv(folder / "est.csv", perturb(truth, rng)).read_bytes(),
        "mcap": mcap,
        "mcap-truncated": mcap[: len(mcap) // 2],
        "random": rng.bytes(2000),
    }


def _with_recordings(case: Any, picks: list[str], recordings: dict[str, bytes]) -> None:
    """Put the picked recordings into a generated multipart body.

    The file parts take the picks in order ("generated" keeps schemathesis' bytes). In a
    one-shot /evaluate body the remaining picks become the estimate files (replacing
    generated selectors), and options that are not a JSON object become cheap ones
    (result.json only), so that some examples run a whole evaluation in the request
    without rendering a PDF each time; the plain with-key test fuzzes those fields.
    """
    if case.operation.path not in MULTIPART or not isinstance(case.body, dict):
        return
    chosen = iter(picks)

    def pick(value: object) -> object:
        name = next(chosen, "generated")
        return value if name == "generated" else recordings[name]

    for field in sorted(FILE_FIELDS & case.body.keys()):
        value = case.body[field]
        case.body[field] = [pick(v) for v in value] if isinstance(value, list) else pick(value)
    rest = [recordings[name] for name in chosen if name != "generated"]
    if case.operation.path == "/api/v1/evaluate" and rest:
        case.body["estimate"] = rest
        case.body.pop("estimate_selector", None)
        if not _is_json_object(case.body.get("options")):
            case.body["options"] = json.dumps({"formats": ["result.json"]})


def _is_json_object(text: object) -> bool:
    try:
        return isinstance(text, str) and isinstance(json.loads(text), dict)
    except json.JSONDecodeError:
        return False


def problem_json(_ctx: object, response: Any, case: Any) -> None:
    """Every error response is an RFC 9457 problem whose status is the HTTP status."""
    if response.status_code < 400 or case.method == "HEAD":  # a HEAD answer has no body
        return
    content_type = response.headers.get("content-type", [""])[0].split(";")[0]
    assert content_type == PROBLEM_JSON, (case.operation.label, response.status_code, content_type)
    body = json.loads(response.content)
    assert isinstance(body, dict), body
    assert body.keys() >= PROBLEM_KEYS, body
    assert body["status"] == response.status_code, body
    assert isinstance(body["detail"], str), body
    assert body["detail"], body
    # a traceback, not the word: a generated id "Traceback" is echoed in a 404's detail
    assert "Traceback (most recent call last)" not in response.text


def test_schema_is_the_served_one(api: Api) -> None:
    """The document fuzzed here is the one /openapi.json serves, with every route in it."""
    served = api.client.get("/openapi.json").json()
    assert served == SPEC
    assert len(list(schema.get_all_operations())) == sum(len(ops) for ops in SPEC["paths"].values())


@api_schema.parametrize()
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
    phases=[Phase.explicit, Phase.generate],  # a failure is reported as found, not shrunk
)
def test_api_with_key(case: Any, api: Api) -> None:
    """With a valid key: no 500, responses as documented, every error a problem document."""
    _call_with_key(case, api)


@schema.include(path_regex="^/api/v1/(datasets|evaluate)$", method="POST").parametrize()
@schema.given(picks=st.lists(st.sampled_from(RECORDINGS), min_size=2, max_size=4))
@settings(
    max_examples=OTHER_EXAMPLES,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
    phases=[Phase.generate],  # the schema's examples cannot fill `picks`
)
def test_uploads_of_recordings(
    case: Any,
    picks: list[str],
    api: Api,
    recordings: dict[str, bytes],
) -> None:
    """Uploads of real, damaged and random files: no 500, every error a problem document."""
    _with_recordings(case, picks, recordings)
    _call_with_key(case, api)


@pytest.mark.parametrize(
    ("path", "body", "status"),
    [
        ("/api/v1/datasets", {"file": "tum", "name": "run 1", "tags": "a, b"}, 201),
        ("/api/v1/datasets", {"file": "mcap"}, 201),
        ("/api/v1/datasets", {"file": "mcap-truncated"}, 422),
        ("/api/v1/evaluate", {"reference": "tum", "estimate": ["csv", "tum"]}, 202),
        ("/api/v1/evaluate", {"reference": "mcap", "estimate_selector": ["/pose"]}, 422),
    ],
)
def test_upload_cases(
    path: str, body: dict[str, Any], status: int, api: Api, recordings: dict[str, bytes]
) -> None:
    """Hand-made multipart cases: the success bodies conform to the schema too."""
    files = {"file", "reference", "estimate"}
    payload: dict[str, Any] = {
        k: ([recordings[n] for n in v] if isinstance(v, list) else recordings[v])
        if k in files
        else v
        for k, v in body.items()
    }
    if path == "/api/v1/evaluate":
        payload["options"] = json.dumps({"formats": ["result.json"]})
    case = schema[path]["POST"].Case(body=payload, media_type="multipart/form-data")
    response = case.call_and_validate(
        headers=bearer(api.key),
        checks=CHECKS,
        excluded_checks=[positive_data_acceptance],
        additional_checks=[problem_json],
    )
    expected = {201, 200} if status == 201 else {status}  # 200: uploaded by an earlier test
    assert response.status_code in expected
    if status == 202:
        assert response.json()["status"] == "succeeded"


def _options_of(body: object) -> dict[str, Any]:
    """Return the evaluation options of a JSON body (a schedule's are in its template)."""
    if not isinstance(body, dict):
        return {}
    template = body.get("template")
    options = (template if isinstance(template, dict) else body).get("options")
    return options if isinstance(options, dict) else {}


def _unexpressible(case: Any) -> list[str]:
    """Return the rules the schema cannot state that a JSON body may break (empty: none).

    Each is in the field's description and the server refuses a request that breaks it
    with 422 and the rule's message; the positive check is off for exactly those bodies.
    """
    body = case.body if isinstance(case.body, dict) else {}
    options = _options_of(body)
    rules = []
    offset = options.get("offset")
    if isinstance(offset, str) and len(offset.replace(",", " ").split()) == 7:
        rules.append("offset: its quaternion must have unit norm")
    if options.get("site_matrix") is not None:
        rules.append("site_matrix: a rotation with uniform scale and a translation")
    fail_on = options.get("fail_on")
    if isinstance(fail_on, list):  # a gate that could never close is refused
        conditions = {c for c in fail_on if isinstance(c, str)}
        if "worse" in conditions and options.get("baseline") is None:
            rules.append("fail_on: worse judges a baseline, which must be given")
        if {"fail", "undecided"} & conditions and not options.get("tolerance"):
            rules.append("fail_on: fail and undecided judge a tolerance, which must be given")
    if body.get("webhook_url") is not None:
        # Whether a host resolves, and to a public address or one the administrator
        # allows (LOCEVAL_WEBHOOK_ALLOW), is the network's and the settings' to say.
        rules.append("webhook_url: resolves to an allowed address")
    cron = body.get("cron")
    if isinstance(cron, str) and len(cron.split()) == 5:
        day, month = cron.split()[2:4]
        if month != "*" and any(d in day for d in ("29", "30", "31")):
            rules.append("cron: a day of the month that the months have (never fires)")
    return rules


def _call_with_key(case: Any, api: Api) -> None:
    excluded = []
    if case.operation.path in MULTIPART:
        # An upload's bytes must be a recording (else 422): the schema can only say
        # "binary". Generated bytes are never one, so valid-by-schema uploads are refused.
        excluded.append(positive_data_acceptance)
        # Every multipart field is text on the wire, so a "wrong type" for a text field
        # (null, 12, true) arrives as the valid string "null", "12", "true" and is rightly
        # taken: negative examples of multipart bodies are not negative on the wire.
        excluded.append(negative_data_rejection)
    elif _unexpressible(case) or case.operation.path.startswith("/api/v1/uploads"):
        # A resumable upload's request is valid only at the upload's offset, within its
        # length, for an upload that exists: state no schema can state (409, 413, 404).
        excluded.append(positive_data_acceptance)
    case.call_and_validate(
        headers=bearer(api.key),
        checks=CHECKS,
        excluded_checks=excluded,
        additional_checks=[problem_json],
    )


@api_schema.parametrize()
@settings(
    max_examples=OTHER_EXAMPLES,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
    phases=[Phase.explicit, Phase.generate],
)
def test_api_without_key(case: Any, api: Api) -> None:
    """Without a key (or with a generated one) nothing is reached: 401 or a routing error."""
    headers = {k: v for k, v in (case.headers or {}).items() if k.lower() != "authorization"}
    if case.headers and any(k.lower() == "authorization" for k in case.headers):
        headers["Authorization"] = "Bearer lcv_" + "0" * 43  # a well-formed key nobody holds
    case.headers = headers
    before = api.stored()
    response = case.call()
    problem_json(None, response, case)
    body = response.json() if case.method != "HEAD" else {"type": "http"}  # HEAD: no body
    if response.status_code != 401:
        # The path did not lead to an endpoint, so there was nothing to authenticate.
        assert response.status_code in {404, 405}, body
        assert body["type"] == "http", body
    else:
        assert response.headers["www-authenticate"] == ["Bearer"]
    assert api.stored() == before


@schema.include(path_regex="^/(healthz|readyz)$").parametrize()
@settings(max_examples=5, deadline=None, suppress_health_check=list(HealthCheck))
def test_probes(case: Any, api: Api) -> None:
    """The probes need no key and answer 200."""
    assert api.app is not None
    response = case.call_and_validate(checks=CHECKS, additional_checks=[problem_json])
    if case.method == "GET":
        assert response.status_code == 200
        assert response.json()["status"] in {"ok", "ready"}
