"""``loceval report`` takes evo result zips beside recordings, as a schedule does (issue 28)."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from tests.bagfactory import POSE, Poses, pose_records, random_poses, write_bag
from tests.exporters._html_tables import html_tables

EVO = Path(__file__).parents[2] / "data" / "evo_results"
EVO_APE_RMSE = 0.5123009339164919
"""evo_ape's rmse of nav2_amcl_odom_ape_se3.zip."""


def _bag(tmp_path: Path, rng: np.random.Generator, name: str) -> Path:
    truth = random_poses(rng, 100, dt_ns=50_000_000)
    moved = truth.positions + rng.normal(scale=0.03, size=truth.positions.shape)
    records = pose_records("/gt", POSE, truth)
    records += pose_records("/est", POSE, Poses(truth.stamps_ns, moved, truth.quats))
    return write_bag(tmp_path / f"{name}.bag", records, fmt="rosbag1")


def _template(tmp_path: Path) -> Path:
    """evo_ape's -a: the nearest stamp within 10 ms, SE(3); the estimate named by its topic."""
    path = tmp_path / "template.json"
    options = {"association": "nearest", "max_dt_s": 0.01, "align": "se3"}
    body = {"reference": {"selector": "/gt"}, "estimates": [{"selector": "/est"}]}
    path.write_text(json.dumps({**body, "options": options}))
    return path


def _report(tmp_path: Path, files: list[Path]) -> tuple[str, str]:
    out = tmp_path / "weekly"
    argv = ["report", "--datasets", *map(str, files), "--template", str(_template(tmp_path))]
    assert main([*argv, "--out", str(out), "--formats", "summary.html"]) == 0
    return (out / "summary.html").read_text()


def test_evo_zips_join_the_offline_summary(tmp_path: Path, rng, capsys) -> None:
    """A committed evo zip is a row with evo's RMSE, marked evo; a broken one a failed row."""
    broken = tmp_path / "broken.zip"
    with zipfile.ZipFile(broken, "w") as archive:
        archive.writestr("info.json", "{")
        archive.writestr("stats.json", "{}")
    bag = _bag(tmp_path, rng, "run0")
    html = _report(tmp_path, [bag, EVO / "nav2_amcl_odom_ape_se3.zip", broken])
    printed = capsys.readouterr().out
    assert "nav2_amcl_odom_ape_se3.zip: succeeded, /odom ATE 0.512 m" in printed
    assert "broken.zip: failed" in printed
    assert "info.json or stats.json is not valid JSON" in printed
    rows = html_tables(html, key="class")["data summary-runs"]
    evo_row = next(r for r in rows if r[1].startswith("nav2_amcl_odom_ape_se3.zip"))
    assert "evo" in evo_row[1]
    assert f"{EVO_APE_RMSE:.3f}" in evo_row
    assert html.count('class="badge badge-source"') == 2  # the broken zip's row is evo's too


def _evo_ape() -> str:
    """Return evo_ape's path, or skip: evo is GPL and never a dependency."""
    folder = os.environ.get("LOCEVAL_EVO_BIN")
    path = shutil.which("evo_ape", path=folder) if folder else shutil.which("evo_ape")
    if path is None:
        pytest.skip(
            "evo's evo_ape is not installed (in a scratch venv: python3 -m venv EVO && "
            "EVO/bin/pip install evo, then LOCEVAL_EVO_BIN=EVO/bin)"
        )
    return path


def test_a_zip_evo_writes_now_stands_beside_loceval_on_the_same_recording(
    tmp_path: Path, rng, capsys
) -> None:
    """With evo installed: its zip of a recording gives the figure loceval gives it (1e-6)."""
    evo_ape = _evo_ape()
    bag = _bag(tmp_path, rng, "run0")
    zipped = tmp_path / "evo_run0.zip"
    subprocess.run(
        [evo_ape, "bag", str(bag), "/gt", "/est", "-a", "--no_warnings", "--save_results",
         str(zipped)],
        env={**os.environ, "MPLBACKEND": "Agg"}, check=True, capture_output=True, timeout=300,
    )  # fmt: skip
    with zipfile.ZipFile(zipped) as archive:
        evo_rmse = json.loads(archive.read("stats.json"))["rmse"]
        evo_n = np.load(io.BytesIO(archive.read("error_array.npy"))).size
    html = _report(tmp_path, [bag, zipped])
    rows = html_tables(html, key="class")["data summary-runs"]
    loceval_row = next(r for r in rows[2:] if r[1] == "run0.bag")
    evo_row = next(r for r in rows[2:] if r[1].startswith("evo_run0.zip"))
    assert rows[0][2:] == ["/est"]  # one system: the zip's est_name is the template's topic
    assert loceval_row[2] == f"{evo_rmse:.3f}"
    assert evo_row[2:] == [f"{evo_rmse:.3f}", "—", "—"]
    assert evo_n == 100
    argv = ["evaluate", f"{bag}@/gt", f"{bag}@/est", "--associate", "nearest", "--max-dt",
            "0.01", "--align", "se3", "--no-ci", "--json"]  # fmt: skip
    capsys.readouterr()
    assert main(argv) == 0
    ours = json.loads(capsys.readouterr().out)["estimates"][0]["ate"]["translation_m"]["rmse"]
    assert ours == pytest.approx(evo_rmse, rel=1e-6)
    stats = html_tables(html, key="class")["data stats summary-stats"]
    assert stats[-1][1] == "2"  # /est over two runs: loceval's and evo's
