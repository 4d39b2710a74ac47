"""The HTTP API's happy paths: uploads, datasets, evaluations, artifacts, one-shot, probes."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.db import Evaluation, EvaluationStatus
from service.jobs import evaluations
from tests import bagfactory
from tests.factories import (
    ROVER_URDF,
    make_trajectory,
    perturb,
    write_csv,
    write_euroc,
    write_kitti,
    write_motive,
    write_tum,
)
from tests.service._api_fixtures import Api, api_routes, assert_problem, tum_pair

CHEAP = {"formats": ["result.json"]}
"""Options that skip the reports and CAD files (the full set is tested once)."""


@pytest.fixture
def tum(rng: np.random.Generator, tmp_path: Path) -> tuple[bytes, bytes]:
    """A TUM reference and a noisy TUM estimate of it (200 poses, 100 Hz)."""
    return tum_pair(rng, tmp_path)


@pytest.fixture
def datasets(api: Api, tum: tuple[bytes, bytes]) -> tuple[str, str]:
    """The ids of the uploaded reference and estimate."""
    reference = api.dataset("truth.txt", tum[0])
    estimate = api.dataset("slam.txt", tum[1])
    return reference["id"], estimate["id"]


def evaluation_body(
    reference: str, *estimates: str, options: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Return a POST /evaluations body for plain trajectory files."""
    return {
        "reference": {"dataset_id": reference},
        "estimates": [{"dataset_id": e} for e in estimates],
        "options": CHEAP if options is None else options,
    }


# --- uploads ---------------------------------------------------------------------------


def test_upload_tum(api: Api, tum: tuple[bytes, bytes]) -> None:
    """A TUM upload is 201 with its kind, hash, size, Location and one file source."""
    response = api.upload("truth.txt", tum[0])
    assert response.status_code == 201
    dataset = response.json()
    assert response.headers["location"] == f"http://127.0.0.1:8000/api/v1/datasets/{dataset['id']}"
    assert dataset["kind"] == "tum"
    assert dataset["filename"] == "truth.txt"
    assert dataset["name"] == "truth.txt"
    assert dataset["size_bytes"] == len(tum[0])
    assert dataset["sha256"] == hashlib.sha256(tum[0]).hexdigest()
    assert dataset["tags"] == []
    inspection = dataset["inspection"]
    assert inspection["kind"] == "tum"
    [source] = inspection["sources"]
    assert source["selector"] is None
    assert source["kind"] == "file"
    assert source["pose_count"] == 200
    assert source["first_stamp_ns"] == 1_700_000_000 * 10**9
    assert source["duration_s"] == pytest.approx(1.99, abs=1e-6)
    stored = api.data_dir / "datasets" / dataset["id"] / "truth.txt"
    assert stored.read_bytes() == tum[0]


@pytest.mark.parametrize("fmt", ["tum", "euroc", "kitti", "csv", "motive"])
def test_upload_text_formats(api: Api, rng: np.random.Generator, tmp_path: Path, fmt: str) -> None:
    """Each text format is recognised from its content and listed with its sources."""
    truth = make_trajectory(rng, 100)
    path = tmp_path / f"run.{'csv' if fmt in {'euroc', 'csv', 'motive'} else 'txt'}"
    if fmt == "tum":
        write_tum(path, truth)
    elif fmt == "euroc":
        write_euroc(path, truth)
    elif fmt == "kitti":
        write_kitti(path, truth)
    elif fmt == "csv":
        write_csv(path, truth)
    else:
        write_motive(path, {"Drone": truth, "Rover": perturb(truth, rng)})
    dataset = api.dataset(path.name, path.read_bytes())
    assert dataset["kind"] == fmt
    sources = dataset["inspection"]["sources"]
    if fmt == "motive":
        assert [s["selector"] for s in sources] == ["Drone", "Rover"]
        assert {s["kind"] for s in sources} == {"rigid_body"}
    else:
        assert [(s["selector"], s["kind"]) for s in sources] == [(None, "file")]
    assert all(s["pose_count"] == 100 for s in sources)


@pytest.mark.parametrize(
    ("fmt", "kind"),
    [("rosbag1", "rosbag1"), ("sqlite3", "rosbag2-sqlite3"), ("mcap", "rosbag2-mcap")],
)
def test_upload_bags(
    api: Api, rng: np.random.Generator, tmp_path: Path, fmt: str, kind: str
) -> None:
    """Bags (ROS 1, a zipped ROS 2 folder, an MCAP file) list their topics and tf chains."""
    poses = bagfactory.random_poses(rng, 30, dt_ns=20_000_000)
    records = bagfactory.pose_records("/pose", bagfactory.POSE, poses) + bagfactory.tf_records(
        bagfactory.link_transforms("map", "base_link", poses)
    )
    written = bagfactory.write_bag(bagfactory.bag_path(tmp_path, fmt), records, fmt=fmt)
    if fmt == "rosbag1":
        name, content = "run.bag", written.read_bytes()
    elif fmt == "sqlite3":
        name, content = (
            "run.zip",
            bagfactory.zip_directory(written, tmp_path / "r.zip").read_bytes(),
        )
    else:
        name, content = "run.mcap", next(written.glob("*.mcap")).read_bytes()
    dataset = api.dataset(name, content)
    assert dataset["kind"] == kind
    inspection = dataset["inspection"]
    assert inspection["format"] == "bag"
    selectors = {s["selector"] for s in inspection["sources"]}
    assert {"/pose", "tf:map:base_link"} <= selectors
    assert "/pose" in {t["name"] for t in inspection["topics"]}


def test_upload_urdf(api: Api) -> None:
    """A URDF is stored as a device file with its links (and no trajectory source)."""
    dataset = api.dataset("rover.urdf", ROVER_URDF.encode())
    assert dataset["kind"] == "urdf"
    assert dataset["inspection"]["links"] == ["rigid_body", "camera_link"]
    assert dataset["inspection"]["sources"] == []


def test_same_bytes_are_deduplicated(api: Api, tum: tuple[bytes, bytes]) -> None:
    """The same bytes again give 200 and the same dataset; another project gets its own.

    The second upload's tags are merged into the dataset and its name is not applied; the
    ``upload`` report says both.
    """
    first = api.upload("truth.txt", tum[0], tags="site-a")
    assert first.json()["upload"] == {
        "deduplicated": False,
        "tags_added": ["site-a"],
        "name_kept": None,
        "notes": [],
    }
    again = api.upload("other-name.txt", tum[0], name="second name", tags="level-2, site-a")
    assert (first.status_code, again.status_code) == (201, 200)
    merged = again.json()
    assert merged["id"] == first.json()["id"]
    assert merged["name"] == "truth.txt"
    assert merged["tags"] == ["site-a", "level-2"]
    report = merged["upload"]
    assert report["deduplicated"] is True
    assert report["tags_added"] == ["level-2"]
    assert report["name_kept"] == "truth.txt"
    assert "'second name' of this request was not applied" in " ".join(report["notes"])
    assert again.headers["location"].endswith(first.json()["id"])
    theirs = api.upload("truth.txt", tum[0], headers=api.other_headers)
    assert theirs.status_code == 201
    assert theirs.json()["id"] != first.json()["id"]
    assert theirs.json()["sha256"] == first.json()["sha256"]
    assert len(list((api.data_dir / "datasets").iterdir())) == 2
    assert list((api.data_dir / "incoming").iterdir()) == []


def test_name_and_tags(api: Api, tum: tuple[bytes, bytes]) -> None:
    """Name and comma-separated tags are stored trimmed, unique and in order."""
    dataset = api.dataset(
        "truth.txt", tum[0], name="  Hall B, run 3 ", tags=" site-a, level 2,,site-a "
    )
    assert dataset["name"] == "Hall B, run 3"
    assert dataset["tags"] == ["site-a", "level 2"]
    assert dataset["filename"] == "truth.txt"


def test_unsafe_filename_is_stored_safely(api: Api, tum: tuple[bytes, bytes]) -> None:
    """A client file name with folders and odd characters is stored as a plain name."""
    dataset = api.dataset("../../etc/run one;rm.txt", tum[0])
    assert dataset["filename"] == "run_one_rm.txt"
    assert (api.data_dir / "datasets" / dataset["id"] / "run_one_rm.txt").is_file()


# --- listing, reading, deleting --------------------------------------------------------


def test_list_datasets(api: Api, rng: np.random.Generator, tmp_path: Path) -> None:
    """The list is newest first, filters by tag, pages with limit/offset, counts all."""
    ids = []
    for k in range(4):
        path = write_tum(tmp_path / f"run{k}.txt", make_trajectory(rng, 20))
        tags = "even" if k % 2 == 0 else "odd"
        ids.append(api.dataset(path.name, path.read_bytes(), tags=tags)["id"])
    listing = api.client.get("/api/v1/datasets", headers=api.headers).json()
    assert [d["id"] for d in listing["items"]] == ids[::-1]
    assert listing["count"] == 4
    even = api.client.get("/api/v1/datasets", params={"tag": "even"}, headers=api.headers).json()
    assert [d["id"] for d in even["items"]] == [ids[2], ids[0]]
    assert even["count"] == 2
    page = api.client.get(
        "/api/v1/datasets", params={"limit": 2, "offset": 1}, headers=api.headers
    ).json()
    assert [d["id"] for d in page["items"]] == [ids[2], ids[1]]
    assert page["count"] == 4
    past = api.client.get("/api/v1/datasets", params={"offset": 10}, headers=api.headers).json()
    assert past == {"items": [], "count": 4}
    none = api.client.get("/api/v1/datasets", params={"tag": "nope"}, headers=api.headers).json()
    assert none == {"items": [], "count": 0}


def test_list_is_per_project(api: Api, tum: tuple[bytes, bytes]) -> None:
    """Another project's list does not show this project's datasets."""
    api.dataset("truth.txt", tum[0])
    theirs = api.client.get("/api/v1/datasets", headers=api.other_headers).json()
    assert theirs == {"items": [], "count": 0}


def test_read_dataset(api: Api, tum: tuple[bytes, bytes]) -> None:
    """GET of one dataset returns what the upload returned."""
    dataset = api.dataset("truth.txt", tum[0], tags="x")
    response = api.client.get(f"/api/v1/datasets/{dataset['id']}", headers=api.headers)
    assert response.status_code == 200
    assert "upload" not in response.json()  # the upload's report is in its answer only
    assert response.json() == {k: v for k, v in dataset.items() if k != "upload"}


def test_delete_dataset(api: Api, tum: tuple[bytes, bytes]) -> None:
    """DELETE answers 204 and removes the row and the file; the id is then unknown."""
    dataset = api.dataset("truth.txt", tum[0])
    folder = api.data_dir / "datasets" / dataset["id"]
    assert folder.is_dir()
    url = f"/api/v1/datasets/{dataset['id']}"
    response = api.client.delete(url, headers=api.headers)
    assert response.status_code == 204
    assert response.content == b""
    assert not folder.exists()
    assert_problem(api.client.get(url, headers=api.headers), 404, type_="not_found")
    assert_problem(api.client.delete(url, headers=api.headers), 404, type_="not_found")
    assert api.upload("truth.txt", tum[0]).status_code == 201  # uploadable again


@pytest.mark.parametrize("status", [EvaluationStatus.QUEUED, EvaluationStatus.RUNNING])
def test_delete_refused_while_in_use(api: Api, datasets: tuple[str, str], status: str) -> None:
    """A dataset that a queued or running evaluation uses cannot be deleted (409)."""
    reference, estimate = datasets
    evaluation_id = api.insert_evaluation([reference, estimate], status=status)
    url = f"/api/v1/datasets/{estimate}"
    assert_problem(
        api.client.delete(url, headers=api.headers),
        409,
        type_="conflict",
        detail=r"'slam\.txt' is used by an evaluation that has not finished",
    )
    assert (api.data_dir / "datasets" / estimate).is_dir()
    with api.app.state.runtime.sessions() as session:
        session.get_one(Evaluation, evaluation_id).status = EvaluationStatus.SUCCEEDED
        session.commit()
    assert api.client.delete(url, headers=api.headers).status_code == 204


def test_finished_evaluation_outlives_its_datasets(api: Api, datasets: tuple[str, str]) -> None:
    """Deleting the inputs of a finished evaluation keeps its result and artifacts."""
    evaluation = api.evaluate(evaluation_body(*datasets)).json()
    for dataset_id in datasets:
        url = f"/api/v1/datasets/{dataset_id}"
        assert api.client.delete(url, headers=api.headers).status_code == 204
    url = f"/api/v1/evaluations/{evaluation['id']}"
    again = api.client.get(url, headers=api.headers).json()
    assert again["status"] == "succeeded"
    assert again["result"]["estimates"][0]["name"] == "slam"
    artifact = api.client.get(f"{url}/artifacts/result.json", headers=api.headers)
    assert artifact.status_code == 200


# --- evaluations -----------------------------------------------------------------------


def test_create_evaluation(api: Api, datasets: tuple[str, str]) -> None:
    """202 with a Location; in immediate mode the job has run: summary, result, artifacts."""
    reference, estimate = datasets
    body = evaluation_body(reference, estimate, options={**CHEAP, "tolerance": "0.10@95"})
    body["estimates"][0]["name"] = "SLAM run"
    response = api.evaluate(body)
    assert response.status_code == 202
    evaluation = response.json()
    url = f"http://127.0.0.1:8000/api/v1/evaluations/{evaluation['id']}"
    assert response.headers["location"] == url
    assert evaluation["status"] == "succeeded"
    assert evaluation["progress"] == {"stage": "done", "fraction": 1.0}
    assert evaluation["attempts"] == 1
    assert evaluation["error"] is None
    assert evaluation["result"] is None  # only GET of one evaluation carries it
    assert evaluation["reference"] == {"dataset_id": reference, "selector": None, "name": None}
    assert evaluation["options"]["tolerance"] == "0.10@95"
    assert evaluation["options"]["association"] == "interpolate"  # the CLI's defaults filled in
    [row] = evaluation["summary"]
    assert row["name"] == "SLAM run"
    assert row["matched"] == 200
    assert 0.0 < row["ate_rmse_m"] < 0.05
    assert row["rpe_rmse_m"] > 0.0
    assert row["verdict"] == "pass"
    assert [a["name"] for a in evaluation["artifacts"]] == ["result.json"]
    assert evaluation["artifacts"][0]["url"] == f"{url}/artifacts/result.json"
    full = api.client.get(f"/api/v1/evaluations/{evaluation['id']}", headers=api.headers).json()
    assert full["result"]["estimates"][0]["name"] == "SLAM run"
    assert full["result"]["evaluation_id"] == evaluation["id"]
    assert {i["sha256"] for i in full["result"]["inputs"]} >= {
        d["sha256"] for d in api.client.get("/api/v1/datasets", headers=api.headers).json()["items"]
    }


def test_intervals_options(api: Api, datasets: tuple[str, str]) -> None:
    """no_ci nulls the intervals; reference_sigma_m adds the reference-error block."""
    reference, estimate = datasets
    runs = {}
    for key, extra in (
        ("plain", {"reference_sigma_m": 0.0002}),
        ("no_ci", {"no_ci": True}),
    ):
        evaluation = api.evaluate(
            evaluation_body(reference, estimate, options={**CHEAP, **extra})
        ).json()
        assert evaluation["status"] == "succeeded", evaluation["error"]
        assert evaluation["options"] | extra == evaluation["options"]
        url = f"/api/v1/evaluations/{evaluation['id']}"
        runs[key] = api.client.get(url, headers=api.headers).json()["result"]
    plain = runs["plain"]["estimates"][0]
    lo, hi = plain["ate"]["translation_m"]["ci95"]["rmse"]
    assert lo <= plain["ate"]["translation_m"]["rmse"] <= hi
    assert plain["reference_error"]["ate"]["adequate"] is True
    off = runs["no_ci"]["estimates"][0]
    assert off["ate"]["translation_m"]["ci95"] is None
    assert off["within_ci95"] is None
    assert off["reference_error"] is None


def test_list_evaluations(api: Api, datasets: tuple[str, str]) -> None:
    """Evaluations are listed newest first, without results, filtered by status, paged."""
    ids = [api.evaluate(evaluation_body(*datasets)).json()["id"] for _ in range(3)]
    failing = evaluation_body(*datasets, options={**CHEAP, "time_offset_s": 1000.0})
    failed = api.evaluate(failing).json()
    assert failed["status"] == "failed"
    listing = api.client.get("/api/v1/evaluations", headers=api.headers).json()
    assert [e["id"] for e in listing["items"]] == [failed["id"], *ids[::-1]]
    assert listing["count"] == 4
    assert all(e["result"] is None for e in listing["items"])
    done = api.client.get(
        "/api/v1/evaluations", params={"status": "succeeded", "limit": 2}, headers=api.headers
    ).json()
    assert [e["id"] for e in done["items"]] == ids[:0:-1]
    assert done["count"] == 3
    theirs = api.client.get("/api/v1/evaluations", headers=api.other_headers).json()
    assert theirs == {"items": [], "count": 0}


def test_failed_evaluation_carries_its_problem(api: Api, datasets: tuple[str, str]) -> None:
    """A job that fails (no overlap in time) is 'failed' with a problem document, no artifacts."""
    body = evaluation_body(*datasets, options={**CHEAP, "time_offset_s": 1000.0})
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "failed"
    assert evaluation["summary"] is None
    assert evaluation["artifacts"] is None
    error = evaluation["error"]
    assert error["status"] == 422
    assert error["type"].startswith("association")
    assert error["detail"]


def test_device_offset_from_urdf(api: Api, datasets: tuple[str, str]) -> None:
    """A URDF dataset gives the rigid body -> sensor offset by its link names."""
    urdf = api.dataset("rover.urdf", ROVER_URDF.encode())
    device = {"dataset_id": urdf["id"], "from_link": "rigid_body", "to_link": "camera_link"}
    evaluation = api.evaluate(evaluation_body(*datasets, options={**CHEAP, "device": device}))
    assert evaluation.status_code == 202
    assert evaluation.json()["status"] == "succeeded"
    assert evaluation.json()["options"]["device"] == device


def test_bag_sources_by_selector(api: Api, rng: np.random.Generator, tmp_path: Path) -> None:
    """Reference and estimate can both come from one bag, chosen by selectors."""
    poses = bagfactory.random_poses(rng, 50, dt_ns=20_000_000)
    records = bagfactory.pose_records("/pose", bagfactory.POSE, poses) + bagfactory.tf_records(
        bagfactory.link_transforms("map", "base_link", poses)
    )
    bag = bagfactory.write_bag(tmp_path / "run.bag", records, fmt="rosbag1")
    dataset = api.dataset("run.bag", bag.read_bytes())
    body = {
        "reference": {"dataset_id": dataset["id"], "selector": "/pose"},
        "estimates": [{"dataset_id": dataset["id"], "selector": "tf:map:base_link"}],
        "options": CHEAP,
    }
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "succeeded"
    assert evaluation["summary"][0]["name"] == "tf:map:base_link"


OPTION_ERRORS = [
    ({"tolerance": "abc"}, r"tolerance takes METRES@PERCENT like 0\.10@95.*'abc'"),
    ({"tolerance": "0.1@200"}, r"share must be in \(0, 100\] percent"),
    ({"align_first": "ten"}, r"options\.align_first: .*takes a number of poses or seconds"),
    ({"align_first": "1e1s"}, r"options\.align_first: .*must read N\|Ns"),
    ({"tolerance": "1e-1@95"}, r"options\.tolerance: .*must read M@PCT like '0\.10@95'"),
    ({"align_first": "0"}, r"options\.align_first: .*needs at least one pose"),
    (
        {"site": "1 2 3 4", "site_matrix": np.eye(4).tolist()},
        r"either as a site or as a site matrix, not both",
    ),
    ({"site": "1 2"}, r"options\.site: .*takes \"tx ty tz yaw_deg\".*'1 2'"),
    ({"formats": ["report.docx"]}, r"unknown artifact 'report\.docx'; choose from result\.json"),
    ({"offset": "1 2"}, r"options\.offset: .*takes \"x y z qx qy qz qw\""),
    ({"units": "km"}, r"options\.units: Input should be 'mm', 'cm' or 'm'"),
    ({"max_dt_s": 0}, r"options\.max_dt_s: Input should be greater than 0"),
    ({"thresholds_m": [0.1, float("inf")]}, r"options\.thresholds_m\.1"),
    ({"colour": "red"}, r"options\.colour: Extra inputs are not permitted"),
    (
        {
            "offset": "0 0 0",
            "device": {"dataset_id": "{estimate}", "from_link": "a", "to_link": "b"},
        },
        r"either as offset or as device, not both",
    ),
]


@pytest.mark.parametrize(("options", "detail"), OPTION_ERRORS, ids=lambda v: str(v)[:40])
def test_options_are_checked_before_queueing(
    api: Api, datasets: tuple[str, str], options: dict[str, Any], detail: str
) -> None:
    """Unusable options are a 422 problem naming the problem; nothing is queued."""
    text = json.dumps(evaluation_body(*datasets, options=options))  # Infinity for inf
    response = api.client.post(
        "/api/v1/evaluations",
        headers={**api.headers, "content-type": "application/json"},
        content=text.replace("{estimate}", datasets[1]),
    )
    assert_problem(response, 422, detail=detail)
    assert api.evaluation_count() == 0


def test_selectors_are_checked_before_queueing(
    api: Api, datasets: tuple[str, str], rng: np.random.Generator, tmp_path: Path
) -> None:
    """A selector on a TUM file, none or an unknown one on a bag, or a URDF: 422, nothing queued."""
    reference, estimate = datasets
    poses = bagfactory.random_poses(rng, 20, dt_ns=20_000_000)
    bag = bagfactory.write_bag(
        tmp_path / "b.bag",
        bagfactory.pose_records("/pose", bagfactory.POSE, poses),
        fmt="rosbag1",
    )
    bag_id = api.dataset("b.bag", bag.read_bytes())["id"]
    urdf_id = api.dataset("rover.urdf", ROVER_URDF.encode())["id"]
    cases = [
        (
            {"dataset_id": reference, "selector": "/odom"},
            {"dataset_id": estimate},
            r"reference dataset 'truth\.txt' is a tum file with one trajectory; leave its selector",
        ),
        (
            {"dataset_id": reference},
            {"dataset_id": bag_id},
            r"estimate dataset 'b\.bag' is a bag; choose a selector .*: /pose",
        ),
        (
            {"dataset_id": reference},
            {"dataset_id": bag_id, "selector": "/odom"},
            r"has no topic '/odom'; its trajectory sources are: /pose",
        ),
        (
            {"dataset_id": urdf_id},
            {"dataset_id": estimate},
            r"is a URDF, not a trajectory; use it as the device offset",
        ),
    ]
    for ref, est, detail in cases:
        body = {"reference": ref, "estimates": [est], "options": CHEAP}
        assert_problem(api.evaluate(body), 422, type_="input.invalid", detail=detail)
    assert api.evaluation_count() == 0


# --- artifacts -------------------------------------------------------------------------


def test_downloads_are_named_after_the_evaluation(api: Api, datasets: tuple[str, str]) -> None:
    """Each file saves as <estimates>-<name> (RFC 6266 filename* for non-ASCII), not report.pdf."""
    reference, estimate = datasets
    body = evaluation_body(reference, estimate, estimate, options=CHEAP)
    body["estimates"][1]["name"] = "Büro 2"
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "succeeded", evaluation["error"]
    (artifact,) = evaluation["artifacts"]
    assert artifact["filename"] == "slam+Büro_2-result.json"
    response = api.client.get(artifact["url"], headers=api.headers)
    assert response.headers["content-disposition"] == (
        'attachment; filename="slam+Buro_2-result.json"; '
        "filename*=UTF-8''slam%2BB%C3%BCro_2-result.json"
    )
    # without estimate names (their summary not written yet) the id names the files
    assert evaluations.artifact_filename(
        Evaluation(id="e-1", request={"estimates": [{"dataset_id": "d"}]}), "report.pdf"
    ) == ("e-1-report.pdf")


@pytest.mark.pdf
def test_all_artifacts(api: Api, datasets: tuple[str, str]) -> None:
    """With the default formats every artifact is listed and served with its media type."""
    evaluation = api.evaluate(evaluation_body(*datasets, options={})).json()
    assert evaluation["status"] == "succeeded"
    expected = {
        "result.json": ("application/json", "attachment"),
        "errors.csv": ("text/csv", "attachment"),
        "map_cells.csv": ("text/csv", "attachment"),
        "report.html": ("text/html", "inline"),
        "report.pdf": ("application/pdf", "inline"),
        "paths.dxf": ("image/vnd.dxf", "attachment"),
        "paths.3dm": ("model/vnd.3dm", "attachment"),
        "paths.3dm.json": ("application/json", "attachment"),
        "paths.glb": ("model/gltf-binary", "attachment"),
        "paths.ifc": ("application/x-step", "attachment"),
        "viewer.html": ("text/html", "attachment"),
        "junit.xml": ("application/xml", "attachment"),
        "summary.md": ("text/markdown", "attachment"),
    }
    listed = {a["name"]: a for a in evaluation["artifacts"]}
    assert list(listed) == list(expected)
    for name, (media_type, disposition) in expected.items():
        assert listed[name]["media_type"] == media_type
        assert listed[name]["filename"] == f"slam-{name}"  # named after the estimate
        response = api.client.get(listed[name]["url"], headers=api.headers)
        assert response.status_code == 200, name
        assert response.headers["content-type"].split(";")[0] == media_type
        assert response.headers["content-disposition"] == (f'{disposition}; filename="slam-{name}"')
        assert len(response.content) == listed[name]["size_bytes"]
        on_disk = api.data_dir / "evaluations" / evaluation["id"] / "artifacts" / name
        assert response.content == on_disk.read_bytes()
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts"
    assert api.client.get(f"{url}/report.pdf", headers=api.headers).content.startswith(b"%PDF")
    assert api.client.get(f"{url}/paths.glb", headers=api.headers).content.startswith(b"glTF")
    document = api.client.get(f"{url}/result.json", headers=api.headers).json()
    assert document["evaluation_id"] == evaluation["id"]
    assert b"<html" in api.client.get(f"{url}/report.html", headers=api.headers).content.lower()


def test_formats_subset(api: Api, datasets: tuple[str, str]) -> None:
    """Only the asked formats (and result.json, always) are written; the others are 404."""
    options = {"formats": ["paths.dxf", "errors.csv"]}
    evaluation = api.evaluate(evaluation_body(*datasets, options=options)).json()
    names = [a["name"] for a in evaluation["artifacts"]]
    assert names == ["result.json", "errors.csv", "paths.dxf"]
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts"
    csv = api.client.get(f"{url}/errors.csv", headers=api.headers)
    assert csv.status_code == 200
    assert csv.text.splitlines()[0]
    for name in ("report.html", "report.pdf", "paths.glb"):
        assert_problem(
            api.client.get(f"{url}/{name}", headers=api.headers),
            404,
            type_="not_found",
            detail=rf"did not write '{name}' \(its formats left it out\)",
        )


# --- one-shot --------------------------------------------------------------------------


def test_one_shot_with_files(api: Api, tum: tuple[bytes, bytes], tmp_path: Path) -> None:
    """/evaluate stores the files as datasets and runs the evaluation with the options."""
    truth = make_trajectory(np.random.default_rng(7))  # another path than the TUM pair's
    csv = write_csv(tmp_path / "other.csv", perturb(truth, np.random.default_rng(8)))
    response = api.client.post(
        "/api/v1/evaluate",
        headers=api.headers,
        files=[
            ("reference", ("truth.txt", tum[0])),
            ("estimate", ("slam.txt", tum[1])),
            ("estimate", ("other.csv", csv.read_bytes())),
        ],
        data={
            "estimate_name": ["SLAM", "Other"],
            "options": json.dumps({**CHEAP, "tolerance": "0.10@95"}),
        },
    )
    assert response.status_code == 202, response.text
    evaluation = response.json()
    assert response.headers["location"].endswith(f"/api/v1/evaluations/{evaluation['id']}")
    assert evaluation["status"] == "succeeded"
    assert [row["name"] for row in evaluation["summary"]] == ["SLAM", "Other"]
    assert evaluation["summary"][0]["verdict"] == "pass"
    assert evaluation["options"]["tolerance"] == "0.10@95"
    names = {
        d["filename"]
        for d in api.client.get("/api/v1/datasets", headers=api.headers).json()["items"]
    }
    assert names == {"truth.txt", "slam.txt", "other.csv"}
    assert list((api.data_dir / "incoming").iterdir()) == []


def test_one_shot_from_one_bag(api: Api, rng: np.random.Generator, tmp_path: Path) -> None:
    """Without estimate files, the estimates are read from the reference bag by selector."""
    poses = bagfactory.random_poses(rng, 50, dt_ns=20_000_000)
    records = bagfactory.pose_records("/pose", bagfactory.POSE, poses) + bagfactory.tf_records(
        bagfactory.link_transforms("map", "base_link", poses)
    )
    bag = bagfactory.write_bag(tmp_path / "run.mcap", records, fmt="mcap")
    response = api.client.post(
        "/api/v1/evaluate",
        headers=api.headers,
        files=[("reference", ("run.mcap", next(bag.glob("*.mcap")).read_bytes()))],
        data={
            "reference_selector": "/pose",
            "estimate_selector": "tf:map:base_link",
            "options": json.dumps(CHEAP),
        },
    )
    assert response.status_code == 202, response.text
    evaluation = response.json()
    assert evaluation["status"] == "succeeded"
    assert evaluation["reference"]["selector"] == "/pose"
    assert evaluation["estimates"][0]["dataset_id"] == evaluation["reference"]["dataset_id"]
    assert evaluation["estimates"][0]["selector"] == "tf:map:base_link"


def test_one_shot_default_options(api: Api, tum: tuple[bytes, bytes]) -> None:
    """Without an options field the CLI defaults apply."""
    response = api.client.post(
        "/api/v1/evaluate",
        headers=api.headers,
        files=[("reference", ("truth.txt", tum[0])), ("estimate", ("slam.txt", tum[1]))],
        data={"options": ""},
    )
    assert response.status_code == 202, response.text
    assert response.json()["options"]["formats"] is None


# --- probes and documentation ----------------------------------------------------------


def test_health_and_readiness(api: Api) -> None:
    """/healthz and /readyz answer without a key."""
    assert api.client.get("/healthz").json() == {"status": "ok"}
    ready = api.client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json() == {"status": "ready", "database": "ok", "queue": "ok"}


def test_openapi_lists_every_route(api: Api) -> None:
    """/openapi.json documents every API route with its methods; /docs answers."""
    document = api.client.get("/openapi.json").json()
    documented = {
        (path, method.upper()) for path, ops in document["paths"].items() for method in ops
    }
    routes = {(path, method) for method, path in api_routes(api.app)}
    expected = {
        ("/api/v1/datasets", "POST"),
        ("/api/v1/datasets", "GET"),
        ("/api/v1/datasets/{dataset_id}", "GET"),
        ("/api/v1/datasets/{dataset_id}", "DELETE"),
        ("/api/v1/evaluations", "POST"),
        ("/api/v1/evaluations", "GET"),
        ("/api/v1/evaluations/{evaluation_id}", "GET"),
        ("/api/v1/evaluations/{evaluation_id}/artifacts/{name}", "GET"),
        ("/api/v1/evaluate", "POST"),
        ("/healthz", "GET"),
        ("/readyz", "GET"),
    }
    assert expected <= documented  # the contract's routes (others may be added)
    assert routes == documented  # every route of the app is documented
    for path, ops in document["paths"].items():
        for op in ops.values():
            assert ("security" in op) == path.startswith("/api/v1/"), path
    uploads = document["paths"]["/api/v1/datasets"]["post"]["requestBody"]["content"]
    assert uploads["multipart/form-data"]["schema"]["required"] == ["file"]
    docs = api.client.get("/docs")
    assert docs.status_code == 200
    assert "swagger" in docs.text.lower()


# --- public recordings -----------------------------------------------------------------


@pytest.mark.public_data
def test_public_recordings(api: Api, public_data: Path) -> None:
    """Real recordings: TUM RGB-D ground truth vs. RGBD-SLAM, and the Nav2 MCAP's topics."""
    truth = api.dataset(
        "freiburg1_xyz-groundtruth.txt",
        (public_data / "freiburg1_xyz-groundtruth.txt").read_bytes(),
    )
    slam = api.dataset(
        "freiburg1_xyz-rgbdslam.txt", (public_data / "freiburg1_xyz-rgbdslam.txt").read_bytes()
    )
    assert (truth["kind"], slam["kind"]) == ("tum", "tum")
    body = evaluation_body(truth["id"], slam["id"], options={**CHEAP, "max_dt_s": 0.02})
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "succeeded", evaluation["error"]
    [row] = evaluation["summary"]
    assert row["matched"] > 500
    assert 0.005 < row["ate_rmse_m"] < 0.1
    mcap = api.dataset("nav2_turtlebot.mcap", (public_data / "nav2_turtlebot.mcap").read_bytes())
    assert mcap["kind"] == "rosbag2-mcap"
    sources = {s["selector"]: s for s in mcap["inspection"]["sources"]}
    assert sources["/amcl_pose"]["pose_count"] == 135
    assert "/odom" in sources
