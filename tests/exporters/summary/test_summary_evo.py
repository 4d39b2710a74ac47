"""An evo result zip as a run of the summary report: evo's figure, marked evo (issue 28)."""

from __future__ import annotations

import datetime as dt
import json
import zipfile
from pathlib import Path

import pytest

from exporters.report import DEFAULT_TEMPLATES_DIR
from exporters.summary import SummaryInput, SummaryRun, SystemFigures, render_summary_html
from exporters.summary.evo import evo_summary_run, evo_system_name
from exporters.summary.model import system_stats
from loceval.readers.evo_result import read_result_zip
from tests.exporters._html_tables import html_tables

EVO = Path(__file__).parents[2] / "data" / "evo_results"
MONDAY = dt.datetime(2026, 11, 16, 7, 0, tzinfo=dt.UTC)


def _named(tmp_path: Path, est_name: str) -> str:
    """The system name of a zip whose est_name is ``est_name``."""
    path = tmp_path / "named.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("info.json", json.dumps({"title": "APE", "est_name": est_name}))
        archive.writestr("stats.json", json.dumps({"rmse": 1.0}))
    return evo_system_name(read_result_zip(path))


@pytest.mark.parametrize(
    ("est_name", "expected"),
    [
        ("/odom", "/odom"),
        ("/tf:map.base_link", "/tf:map.base_link"),
        ("/home/me/runs/orb.txt", "orb"),
        ("orb_slam3.tum", "orb_slam3"),
        ("C:\\runs\\vins.csv", "vins"),
        ("", "named"),
    ],
)
def test_a_system_is_named_as_loceval_names_it(tmp_path: Path, est_name: str, expected) -> None:
    """A topic stays a topic, a file is named by its stem, no est_name by the zip's stem."""
    assert _named(tmp_path, est_name) == expected


def test_an_ape_zip_fills_the_ate_column_and_says_what_it_lacks() -> None:
    """evo's APE RMSE (translation, metres) is the ATE; no verdict; the note names evo's setup."""
    result = read_result_zip(EVO / "nav2_amcl_odom_ape_se3.zip")
    run = evo_summary_run(result, dataset="archive.zip", recorded_at=MONDAY)
    assert run.source == "evo"
    figures = run.systems["/odom"]
    assert figures == SystemFigures(0.5123009339164919, None, 83, None)
    assert run.source_note is not None
    assert "APE w.r.t. translation part (m), with SE(3) Umeyama alignment" in run.source_note
    assert "evo gives no confidence interval and no verdict" in run.source_note


def test_evo_rows_are_marked_in_the_report_and_counted_in_the_statistics() -> None:
    """The HTML marks the evo row with its badge and note; its RMSE joins the system's mean."""
    loceval_run = SummaryRun(
        dataset="level2-run0.bag",
        recorded_at=MONDAY,
        status="succeeded",
        systems={"/odom": SystemFigures(0.30, 0.02, 100, None)},
    )
    evo_run = evo_summary_run(
        read_result_zip(EVO / "nav2_amcl_odom_ape_se3.zip"),
        dataset="archive.zip",
        recorded_at=MONDAY - dt.timedelta(days=7),
    )
    summary = SummaryInput(
        title="Weekly", generated_at=MONDAY, selection="recordings", runs=[loceval_run, evo_run]
    )
    (stats,) = system_stats(summary.runs)
    assert stats.ate_rmse_m == (0.5123009339164919, 0.30)  # by date: the archive first
    html = render_summary_html(summary, templates_dir=DEFAULT_TEMPLATES_DIR).decode()
    rows = html_tables(html, key="class")["data summary-runs"]
    archive_row = next(r for r in rows if r[1].startswith("archive.zip"))
    assert "evo" in archive_row[1]
    assert archive_row[2:] == ["0.512", "—", "—"]
    assert html.count('class="badge badge-source"') == 1
    assert "1 row marked evo is an uploaded result zip" in html


def test_a_loceval_only_summary_has_no_evo_mark() -> None:
    """Runs loceval evaluated carry no evo badge and no evo note."""
    run = SummaryRun(
        dataset="r.bag",
        recorded_at=MONDAY,
        status="succeeded",
        systems={"A": SystemFigures(0.1, 0.01, 10, None)},
    )
    summary = SummaryInput(title="W", generated_at=MONDAY, selection="s", runs=[run])
    html = render_summary_html(summary, templates_dir=DEFAULT_TEMPLATES_DIR).decode()
    assert 'class="badge badge-source"' not in html
    assert "marked evo" not in html
