"""Classes of bad input the core and readers must refuse clearly (issue 16), over HTTP.

The same classes as ``test_cli_bad_classes``, through the API: every refusal is a 4xx
``application/problem+json`` document that names no server folder (the data directory, the
temporary folder a zipped bag is extracted into) and holds no control characters.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from loceval.errors import ReaderError
from service.errors import problem_for
from tests.factories import make_trajectory, perturb, write_tum
from tests.service._api_fixtures import Api, assert_no_server_paths, assert_problem, open_api
from tests.service.cli.test_cli_bad_classes import EUROC_HEADER, ZIP_CASES, hostile_zips

CHEAP = {"formats": ["result.json"]}
HOSTILE_NAME = "evil\x1b[31m\x07\u202e<script>alert(1)</script>"
"""ESC, BEL, a bidi override and markup (a NUL is refused at the door: see below)."""


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Api]:
    """An app (immediate jobs) shared by the module; tests compare what is stored."""
    with open_api(tmp_path_factory.mktemp("api")) as api:
        yield api


@pytest.fixture(scope="module")
def datasets(api: Api, tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    """Ids of a TUM reference (200 poses, 100 Hz) and a noisy estimate of it."""
    folder = tmp_path_factory.mktemp("tum")
    rng = np.random.default_rng(16)
    truth = make_trajectory(rng, 200)
    reference = write_tum(folder / "reference.txt", truth).read_bytes()
    estimate = write_tum(folder / "estimate.txt", perturb(truth, rng)).read_bytes()
    return api.dataset("truth.txt", reference)["id"], api.dataset("slam.txt", estimate)["id"]


def _body(datasets: tuple[str, str], **options: Any) -> dict[str, Any]:
    return {
        "reference": {"dataset_id": datasets[0]},
        "estimates": [{"dataset_id": datasets[1]}],
        "options": {**CHEAP, **options},
    }


def _assert_clean(detail: str, api: Api, *paths: Path) -> None:
    """No server folder and no control character in a problem's detail."""
    assert_no_server_paths(detail, api.data_dir, *paths)
    assert "/tmp/" not in detail, detail  # noqa: S108  (no temporary folder is shown)
    assert tempfile.gettempdir() not in detail, detail
    assert "loceval-zip" not in detail, detail
    assert not any(ord(ch) < 32 or ch == "\u202e" for ch in detail), detail


# --- 1. zipped bags -----------------------------------------------------------------------


@pytest.mark.parametrize("case", ZIP_CASES)
def test_zipped_bag_uploads_name_members(api: Api, tmp_path: Path, case: str) -> None:
    """A broken zipped bag is a 422 naming ZIP:MEMBER, never the extraction folder."""
    marker = tmp_path / "pwned"
    content, detail = hostile_zips(tmp_path / "make", marker)[case]
    before = api.stored()
    body = assert_problem(api.upload("rec.zip", content), 422, detail=detail)
    assert body["type"].startswith("input.")
    _assert_clean(body["detail"], api, tmp_path)
    assert api.stored() == before
    assert not marker.exists()


def test_problem_for_scrubs_every_server_folder(tmp_path: Path) -> None:
    """The one scrubbing function removes extraction folders, other temp folders, the data dir."""
    data = tmp_path / "data"
    data.mkdir()
    temp = Path(tempfile.gettempdir())
    message = (
        f"Bag 'rec.zip' cannot be read ({temp}/loceval-zip-ab12cd/bag/metadata.yaml, "
        f"{temp}/other-1234/run.db3, {data}/datasets/0b7c1c7e-8e1f-4c55-9d5e-3c1c9b1a2f00/"
        "run.mcap) \x1b[31mred\u202e; re-copy it."
    )
    detail = problem_for(ReaderError(message), private=[data])["detail"]
    assert detail == (
        "Bag 'rec.zip' cannot be read (bag/metadata.yaml, run.db3, run.mcap) "
        "\ufffd[31mred\ufffd; re-copy it."
    )


# --- 2. files without rows ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("filename", "content", "detail"),
    [
        ("data.csv", f"{EUROC_HEADER}\n", r"holds its header .* but no data rows"),
        ("run.txt", "# timestamp tx ty tz qx qy qz qw\n", r"holds only comments .* no data rows"),
        ("run.txt", " \n\n\t\n", r"is empty"),
        ("run.csv", "t,x,y,z\n", r"no rows of numbers under a header"),
    ],
)
def test_files_without_rows(api: Api, filename: str, content: str, detail: str) -> None:
    """Header-only, comment-only and whitespace-only files are 422 (the EuRoC one was a 500)."""
    before = api.stored()
    body = assert_problem(api.upload(filename, content.encode()), 422, detail=detail)
    _assert_clean(body["detail"], api)
    assert api.stored() == before


# --- 3. coordinates that would overflow -------------------------------------------------


@pytest.mark.parametrize(
    ("options", "detail"),
    [
        ({"site": "1e308 0 0 0"}, r"options\.site: The site transform has tx = 1e\+308 m"),
        ({"site": "0 0 0 1e300"}, r"options\.site: .*yaw must be within ±360 degrees"),
        (
            {"site_matrix": [[1, 0, 0, 1e308], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
            r"options\.site_matrix: .*has tx = 1e\+308 m, beyond ±1e\+09 m",
        ),
        ({"offset": "0 1e308 0"}, r"options\.offset: The device offset's x y z .* exceed ±1000 m"),
    ],
)
def test_coordinates_beyond_any_site(
    api: Api, datasets: tuple[str, str], options: dict[str, Any], detail: str
) -> None:
    """A site or offset of 1e308 m is a 422 at submission, not a job failed as a bug."""
    count = api.evaluation_count()
    body = assert_problem(api.evaluate(_body(datasets, **options)), 422, detail=detail)
    assert body["option"].startswith("options.")
    assert api.evaluation_count() == count


# --- 4. EuRoC without orientation --------------------------------------------------------


def test_euroc_without_orientation(api: Api) -> None:
    """EuRoC's header without its q_RS_* columns is a 422 that names them and the csv: prefix."""
    rows = "\n".join(f"{1403715273262142976 + k * 5_000_000},{k},0,0" for k in range(10))
    content = f"#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m]\n{rows}\n".encode()
    body = assert_problem(
        api.upload("gt.csv", content), 422, detail=r"no orientation columns \(q_RS_w, .*csv:"
    )
    _assert_clean(body["detail"], api)


# --- 5. RPE deltas ----------------------------------------------------------------------


@pytest.mark.parametrize(("delta", "unit"), [(1e-12, "s"), (1e-300, "m")])
def test_rpe_delta_below_one_step(
    api: Api, datasets: tuple[str, str], delta: float, unit: str
) -> None:
    """An RPE delta below one sampling step fails the job at once with a 422 and a value."""
    response = api.evaluate(_body(datasets, rpe_delta=delta, rpe_unit=unit))
    assert response.status_code == 202, response.text
    evaluation = response.json()
    assert evaluation["status"] == "failed"
    error = evaluation["error"]
    assert error["status"] == 422
    assert error["option"] == "options.rpe_delta"
    assert "Set options.rpe_delta to" in error["detail"], error["detail"]


# --- 6. names shown as text -------------------------------------------------------------


def test_a_nul_in_a_name_is_refused(api: Api, datasets: tuple[str, str]) -> None:
    """A NUL cannot be stored (PostgreSQL refuses it): 422 naming the field, nothing queued."""
    body = _body(datasets, formats=["result.json"])
    body["estimates"][0]["name"] = "evil\x00name"
    answer = api.client.post("/api/v1/evaluations", json=body, headers=api.headers)
    assert answer.status_code == 422
    assert answer.headers["content-type"].startswith("application/problem+json")
    assert "estimates.0.name" in answer.json()["detail"]
    assert "NUL" in answer.json()["detail"]


def test_hostile_names_reach_no_file_raw(api: Api, datasets: tuple[str, str]) -> None:
    """ESC, BEL, a bidi override and <script> in an estimate's name: none raw in report.html."""
    body = _body(datasets, formats=["report.html", "paths.dxf", "result.json"])
    body["estimates"][0]["name"] = HOSTILE_NAME
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "succeeded", evaluation
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts"
    html = api.client.get(f"{url}/report.html", headers=api.headers).text
    for raw in ("\x1b", "\x07", "\u202e", "<script>alert"):
        assert raw not in html, raw
    assert "evil\ufffd[31m\ufffd\ufffd&lt;script&gt;" in html
    dxf = api.client.get(f"{url}/paths.dxf", headers=api.headers).content
    assert b"\x1b" not in dxf
    assert b"\x07" not in dxf
    assert "\u202e".encode() not in dxf
