"""End to end through HTTP: the real ``loceval serve`` with its real queue consumer.

Uploads the public recordings, evaluates them as background jobs, compares the figures with
the CLI's ``--json`` on the same files, opens every artifact with the library that reads its
format, and checks project isolation, authentication and a failing job's problem document.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import ezdxf
import httpx2
import ifcopenshell
import pypdf
import pytest
import rhino3dm
from junitparser import JUnitXml

from exporters import ARTIFACTS
from tests.exporters.ci.test_summary_md import tables
from tests.service.conftest import (
    LiveServer,
    assert_same_ate,
    cli,
    cli_json,
    submit,
    succeeded,
    upload,
    wait_for_evaluation,
)

pytestmark = [pytest.mark.slow, pytest.mark.public_data]

GROUNDTRUTH = "freiburg1_xyz-groundtruth.txt"
ESTIMATE = "freiburg1_xyz-rgbdslam.txt"
BAG = "nav2_turtlebot.mcap"
# /amcl_pose comes at ~1.4 Hz, so the default interpolation (gaps up to 0.1 s) would match
# only a few poses: nearest neighbours within 50 ms match ~130 of them.
BAG_OPTIONS = {"association": "nearest", "max_dt_s": 0.05}
BAG_CLI_OPTIONS = ("--associate", "nearest", "--max-dt", "0.05")
BAG_ESTIMATES = ("tf:map:base_link", "/odom")
TEXT_ARTIFACTS = frozenset(
    {"result.json", "errors.csv", "report.html", "paths.3dm.json", "viewer.html", "map_cells.csv"}
)


@pytest.fixture(scope="module")
def server(live_server_module: LiveServer) -> LiveServer:
    """The module's server."""
    return live_server_module


@pytest.fixture(scope="module")
def client(server: LiveServer) -> Iterator[httpx2.Client]:
    """A client with the default project's key."""
    with server.client() as http:
        yield http


@pytest.fixture(scope="module")
def fr1(client: httpx2.Client, public_data: Path) -> dict[str, Any]:
    """The fr1 pair uploaded (twice each) and evaluated to the end."""
    first = {name: upload(client, public_data / name) for name in (GROUNDTRUTH, ESTIMATE)}
    again = {name: upload(client, public_data / name, expect=200) for name in first}
    evaluation = submit(
        client,
        {"dataset_id": first[GROUNDTRUTH]["id"]},
        [{"dataset_id": first[ESTIMATE]["id"]}],
    )
    assert evaluation["status"] in {"queued", "running", "succeeded"}
    done = wait_for_evaluation(client, evaluation["id"])
    return {"datasets": first, "again": again, "evaluation": done}


@pytest.fixture(scope="module")
def bag(client: httpx2.Client, public_data: Path) -> dict[str, Any]:
    """The Nav2 MCAP uploaded; /amcl_pose vs tf map->base_link and /odom, evaluated."""
    dataset = upload(client, public_data / BAG, tags="nav2, turtlebot")
    evaluation = submit(
        client,
        {"dataset_id": dataset["id"], "selector": "/amcl_pose"},
        [{"dataset_id": dataset["id"], "selector": s} for s in BAG_ESTIMATES],
        BAG_OPTIONS,
    )
    return {"dataset": dataset, "evaluation": wait_for_evaluation(client, evaluation["id"])}


def _download(client: httpx2.Client, artifact: dict[str, Any]) -> httpx2.Response:
    answer = client.get(artifact["url"])
    assert answer.status_code == 200, (artifact["name"], answer.text[:500])
    return answer


def _check_artifact(
    name: str, answer: httpx2.Response, evaluation: dict[str, Any], tmp_path: Path
) -> None:
    """Open one downloaded artifact with the library that reads its format."""
    content = answer.content
    if name in TEXT_ARTIFACTS:
        assert b"/datasets/" not in content, f"{name} names a server folder"
    if name == "result.json":
        assert json.loads(content) == evaluation["result"]
    elif name == "errors.csv":
        rows = list(csv.reader(io.StringIO(content.decode("utf-8"))))
        assert rows[0][:3] == ["estimate", "stamp_ns", "t_s"]
        assert len(rows) == 1 + sum(e["matched"] for e in evaluation["result"]["estimates"])
    elif name == "map_cells.csv":  # no map in this evaluation: the header and why
        lines = content.decode("utf-8").splitlines()
        assert lines[0] == "x_m,y_m,distance_m,fitted_distance_m,clutter"
        assert lines[1].startswith("# no map was measured")
    elif name in {"report.html", "report.pdf", "viewer.html"}:
        _check_document(name, content, evaluation)
    elif name.startswith("paths."):
        _check_cad_artifact(name, content, evaluation, tmp_path)
    elif name in {"junit.xml", "summary.md"}:
        _check_ci_artifact(name, content, evaluation)
    else:  # pragma: no cover  (a new artifact needs a check here)
        pytest.fail(f"no check for the artifact {name!r}")


def _check_document(name: str, content: bytes, evaluation: dict[str, Any]) -> None:
    """Open a report or the viewer: HTML that is one closed file, a PDF whose text reads."""
    if name == "report.html":
        assert content.lstrip().lower().startswith(b"<!doctype html")
    elif name == "report.pdf":
        reader = pypdf.PdfReader(io.BytesIO(content))
        text = "".join(page.extract_text() for page in reader.pages)
        assert "ATE" in text
        assert evaluation["result"]["estimates"][0]["name"] in text
    else:  # viewer.html, one closed file: its scene names every trajectory
        text = content.decode("utf-8")
        assert text.lstrip().lower().startswith("<!doctype html")
        assert "default-src 'none'" in text
        for estimate in evaluation["result"]["estimates"]:
            assert json.dumps(estimate["name"])[1:-1] in text


def _check_ci_artifact(name: str, content: bytes, evaluation: dict[str, Any]) -> None:
    """Read a CI file as CI systems do: a suite per estimate; a table naming each estimate."""
    names = [e["name"] for e in evaluation["result"]["estimates"]]
    if name == "junit.xml":
        suites = [suite.name for suite in JUnitXml.fromstring(content.decode("utf-8"))]
        assert suites == names
    else:
        cells = {cell for table in tables(content.decode("utf-8")) for row in table for cell in row}
        assert set(names) <= cells


def _check_cad_artifact(
    name: str, content: bytes, evaluation: dict[str, Any], tmp_path: Path
) -> None:
    """Open one CAD file with the library that reads its format."""
    if name == "paths.dxf":
        path = tmp_path / name
        path.write_bytes(content)
        drawing = ezdxf.readfile(path)
        assert any(e.dxftype() == "POLYLINE" for e in drawing.modelspace())
    elif name == "paths.3dm":
        model = rhino3dm.File3dm.FromByteArray(content)
        assert model is not None
        assert len(model.Objects) > 0
    elif name == "paths.3dm.json":
        assert json.loads(content)
    elif name == "paths.glb":
        assert content.startswith(b"glTF")
    elif name == "paths.ifc":
        ifc = ifcopenshell.file.from_string(content.decode("utf-8"))
        trajectories = [a for a in ifc.by_type("IfcAnnotation") if a.ObjectType == "trajectory"]
        assert len(trajectories) == 1 + len(evaluation["result"]["estimates"])
    else:  # pragma: no cover  (a new artifact needs a check here)
        pytest.fail(f"no check for the artifact {name!r}")


def _check_all_artifacts(client: httpx2.Client, evaluation: dict[str, Any], tmp_path: Path) -> None:
    listed = {a["name"]: a for a in evaluation["artifacts"]}
    assert set(listed) == set(ARTIFACTS)
    for name, artifact in listed.items():
        assert artifact["media_type"] == ARTIFACTS[name].media_type
        answer = _download(client, artifact)
        media_type = answer.headers["content-type"].split(";")[0].strip()
        assert media_type == ARTIFACTS[name].media_type, name
        disposition = answer.headers["content-disposition"]
        assert f'filename="{artifact["filename"]}"' in disposition
        size = len(answer.content)
        assert int(answer.headers["content-length"]) == artifact["size_bytes"] == size
        _check_artifact(name, answer, evaluation, tmp_path)


# --- TUM files ---------------------------------------------------------------------------


def test_upload_recognises_tum_and_deduplicates(fr1: dict[str, Any], public_data: Path) -> None:
    """An upload is a TUM dataset with the file's SHA-256; the same bytes again give it back."""
    for name, dataset in fr1["datasets"].items():
        data = (public_data / name).read_bytes()
        assert dataset["kind"] == "tum"
        assert dataset["filename"] == name
        assert dataset["size_bytes"] == len(data)
        assert dataset["sha256"] == hashlib.sha256(data).hexdigest()
        [source] = dataset["inspection"]["sources"]
        assert source["selector"] is None
        assert source["pose_count"] > 0
        assert fr1["again"][name]["id"] == dataset["id"]


@pytest.mark.pdf
def test_evaluation_equals_the_cli(fr1: dict[str, Any], public_data: Path) -> None:
    """The job's ATE equals ``loceval evaluate --json`` on the same files to 1e-12."""
    evaluation = succeeded(fr1["evaluation"])
    assert "/datasets/" not in json.dumps(evaluation)  # no server folders in the result
    expected = cli_json(str(public_data / GROUNDTRUTH), str(public_data / ESTIMATE))
    assert_same_ate(evaluation["result"], expected)
    assert evaluation["attempts"] == 1
    assert evaluation["progress"] == {"stage": "done", "fraction": 1.0}
    [row] = evaluation["summary"]
    ate = expected["estimates"][0]["ate"]["translation_m"]["rmse"]
    assert row["ate_rmse_m"] == pytest.approx(ate, rel=1e-12)
    assert evaluation["result"]["estimates"][0]["name"] == Path(ESTIMATE).stem
    shas = [i["sha256"] for i in evaluation["result"]["inputs"]]
    assert shas == [i["sha256"] for i in expected["inputs"]]


@pytest.mark.pdf
def test_every_artifact_downloads_and_opens(
    fr1: dict[str, Any], client: httpx2.Client, tmp_path: Path
) -> None:
    """Every listed artifact downloads with its media type and a file name, and opens."""
    _check_all_artifacts(client, succeeded(fr1["evaluation"]), tmp_path)


def test_unknown_artifact_is_404(fr1: dict[str, Any], client: httpx2.Client) -> None:
    """An artifact name that does not exist is a 404 problem naming the real ones."""
    answer = client.get(f"/api/v1/evaluations/{fr1['evaluation']['id']}/artifacts/secret.txt")
    assert answer.status_code == 404
    assert answer.headers["content-type"] == "application/problem+json"
    assert "report.pdf" in answer.json()["detail"]


@pytest.mark.pdf
def test_one_shot_evaluate_equals_the_evaluation(
    fr1: dict[str, Any], client: httpx2.Client, public_data: Path
) -> None:
    """POST /evaluate with the two files and options gives the same ATE as the job before."""
    with (public_data / GROUNDTRUTH).open("rb") as ref, (public_data / ESTIMATE).open("rb") as est:
        answer = client.post(
            "/api/v1/evaluate",
            files=[("reference", (GROUNDTRUTH, ref)), ("estimate", (ESTIMATE, est))],
            data={"options": json.dumps({"align": "se3", "units": "m"})},
        )
    assert answer.status_code == 202, answer.text
    created = answer.json()
    assert created["reference"]["dataset_id"] == fr1["datasets"][GROUNDTRUTH]["id"]
    assert created["options"]["units"] == "m"
    done = succeeded(wait_for_evaluation(client, created["id"]))
    assert done["id"] != fr1["evaluation"]["id"]
    assert_same_ate(done["result"], fr1["evaluation"]["result"])


# --- a ROS 2 MCAP bag --------------------------------------------------------------------


def test_mcap_upload_lists_topics_and_tf(bag: dict[str, Any]) -> None:
    """The MCAP is a rosbag2-mcap dataset whose sources include its pose topics and tf chains."""
    dataset = bag["dataset"]
    assert dataset["kind"] == "rosbag2-mcap"
    assert dataset["tags"] == ["nav2", "turtlebot"]
    selectors = {s["selector"] for s in dataset["inspection"]["sources"]}
    assert {"/amcl_pose", "/odom", "tf:map:base_link"} <= selectors


@pytest.mark.pdf
def test_mcap_evaluation_equals_the_cli(
    bag: dict[str, Any], client: httpx2.Client, public_data: Path, tmp_path: Path
) -> None:
    """/amcl_pose vs tf map->base_link and /odom: ATE equals the CLI's; artifacts download."""
    evaluation = succeeded(bag["evaluation"])
    path = public_data / BAG
    estimates = [f"{path}@{selector}" for selector in BAG_ESTIMATES]
    expected = cli_json(f"{path}@/amcl_pose", *estimates, *BAG_CLI_OPTIONS)
    assert all(e["matched"] > 100 for e in expected["estimates"])
    assert_same_ate(evaluation["result"], expected)
    names = [e["name"] for e in evaluation["result"]["estimates"]]
    assert names == list(BAG_ESTIMATES)
    assert [row["name"] for row in evaluation["summary"]] == names
    _check_all_artifacts(client, evaluation, tmp_path)


@pytest.mark.pdf
def test_one_shot_bag_takes_estimates_from_the_reference_file(
    bag: dict[str, Any], client: httpx2.Client, public_data: Path
) -> None:
    """POST /evaluate with only the bag and selectors equals the evaluation of the dataset."""
    with (public_data / BAG).open("rb") as fh:
        answer = client.post(
            "/api/v1/evaluate",
            files=[("reference", (BAG, fh))],
            data={
                "reference_selector": "/amcl_pose",
                "estimate_selector": list(BAG_ESTIMATES),
                "estimate_name": ["map to base_link", "odometry"],
                "options": json.dumps(BAG_OPTIONS),
            },
        )
    assert answer.status_code == 202, answer.text
    created = answer.json()
    dataset_id = bag["dataset"]["id"]
    assert created["reference"] == {
        "dataset_id": dataset_id,
        "selector": "/amcl_pose",
        "name": None,
    }
    assert [e["selector"] for e in created["estimates"]] == list(BAG_ESTIMATES)
    done = succeeded(wait_for_evaluation(client, created["id"]))
    assert [r["name"] for r in done["summary"]] == ["map to base_link", "odometry"]
    assert_same_ate(done["result"], succeeded(bag["evaluation"])["result"])


# --- projects and keys -------------------------------------------------------------------


def test_other_project_sees_nothing(
    fr1: dict[str, Any], server: LiveServer, public_data: Path
) -> None:
    """Another project's key gets 404 for this project's ids, lists nothing; revoked, 401."""
    dataset_id = fr1["datasets"][GROUNDTRUTH]["id"]
    evaluation_id = fr1["evaluation"]["id"]
    key = server.create_key("other site")
    assert key.startswith("lcv_")
    assert key != server.api_key
    with server.client(key) as other:
        for url in (
            f"/api/v1/datasets/{dataset_id}",
            f"/api/v1/evaluations/{evaluation_id}",
            f"/api/v1/evaluations/{evaluation_id}/artifacts/result.json",
        ):
            answer = other.get(url)
            assert answer.status_code == 404, url
            assert answer.headers["content-type"] == "application/problem+json"
            assert answer.json()["type"] == "not_found"
        assert other.delete(f"/api/v1/datasets/{dataset_id}").status_code == 404
        answer = other.post(
            "/api/v1/evaluations",
            json={
                "reference": {"dataset_id": dataset_id},
                "estimates": [{"dataset_id": dataset_id}],
            },
        )
        assert answer.status_code == 404
        assert other.get("/api/v1/datasets").json() == {"items": [], "count": 0}
        assert other.get("/api/v1/evaluations").json()["count"] == 0
        # The same bytes are a new dataset of the other project, not a link to the first's.
        own = upload(other, public_data / GROUNDTRUTH, expect=201)
        assert own["id"] != dataset_id
        assert own["sha256"] == fr1["datasets"][GROUNDTRUTH]["sha256"]
    cli("keys", "revoke", key, env=server.env)
    with server.client(key) as revoked:
        answer = revoked.get("/api/v1/datasets")
    assert answer.status_code == 401
    assert answer.json()["type"] == "auth.unauthorized"


def test_no_key_or_a_wrong_key_is_401(server: LiveServer) -> None:
    """Without a key, or with an unknown one, the API answers 401 problem+json."""
    with server.anonymous_client() as anonymous:
        answer = anonymous.get("/api/v1/datasets")
        assert anonymous.get("/healthz").json() == {"status": "ok"}
    assert answer.status_code == 401
    assert answer.headers["content-type"] == "application/problem+json"
    assert answer.headers["www-authenticate"] == "Bearer"
    problem = answer.json()
    assert problem["status"] == 401
    assert problem["type"] == "auth.unauthorized"
    assert "Authorization: Bearer" in problem["detail"]
    with server.client("lcv_" + "x" * 43) as wrong:
        answer = wrong.get("/api/v1/evaluations")
    assert answer.status_code == 401
    assert "unknown or revoked" in answer.json()["detail"]


def test_evaluations_are_listed_newest_first(fr1: dict[str, Any], client: httpx2.Client) -> None:
    """GET /evaluations lists the project's evaluations newest first, without results."""
    datasets = fr1["datasets"]
    newest = submit(
        client,
        {"dataset_id": datasets[GROUNDTRUTH]["id"]},
        [{"dataset_id": datasets[ESTIMATE]["id"], "name": "newest"}],
        {"formats": ["errors.csv"]},
    )
    listing = client.get("/api/v1/evaluations").json()
    items = listing["items"]
    assert listing["count"] == len(items) >= 2
    assert items[0]["id"] == newest["id"]
    assert fr1["evaluation"]["id"] in {e["id"] for e in items}
    stamps = [e["created_at"] for e in items]
    assert stamps == sorted(stamps, reverse=True)
    assert all(e["result"] is None for e in items)
    done = succeeded(wait_for_evaluation(client, newest["id"]))
    assert {a["name"] for a in done["artifacts"]} == {"result.json", "errors.csv"}


# --- a job that fails --------------------------------------------------------------------


def _write_tum(path: Path, start_s: float, poses: int = 25) -> Path:
    lines = [
        f"{start_s + 0.1 * k:.3f} {0.1 * k:.4f} {0.02 * k * k:.4f} 0.0 0 0 0 1"
        for k in range(poses)
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_disjoint_recordings_fail_with_a_problem(
    server: LiveServer, client: httpx2.Client, tmp_path: Path
) -> None:
    """Recordings that do not overlap in time end failed with a clean association problem."""
    early = upload(client, _write_tum(tmp_path / "early.txt", 1000.0))
    late = upload(client, _write_tum(tmp_path / "late.txt", 5000.0))
    assert early["kind"] == late["kind"] == "tum"
    created = submit(client, {"dataset_id": early["id"]}, [{"dataset_id": late["id"]}])
    failed = wait_for_evaluation(client, created["id"])
    assert failed["status"] == "failed"
    error = failed["error"]
    assert error["type"] == "association.no_matches"
    assert error["status"] == 422
    assert error["title"] == "AssociationError"
    assert "Only 0 of 25 poses" in error["detail"]
    assert "Traceback" not in error["detail"]
    assert str(server.data_dir) not in json.dumps(error)
    assert str(server.data_dir.resolve()) not in json.dumps(error)
    assert failed["artifacts"] is None
    assert failed["summary"] is None
    assert failed["result"] is None
    answer = client.get(f"/api/v1/evaluations/{created['id']}/artifacts/report.pdf")
    assert answer.status_code == 409
    assert answer.json()["type"] == "evaluation.not_ready"
    assert not (server.data_dir / "evaluations" / created["id"] / "artifacts").exists()
