"""``loceval report``: the schedule's summary report from the shell."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli import main
from tests.bagfactory import POSE, Poses, pose_records, random_poses, write_bag


def _bag(tmp_path: Path, rng, name: str, *, noise: float, with_estimate: bool = True) -> Path:
    truth = random_poses(rng, 100, dt_ns=50_000_000)
    records = pose_records("/gt", POSE, truth)
    if with_estimate:
        moved = truth.positions + rng.normal(scale=noise, size=truth.positions.shape)
        records += pose_records("/est", POSE, Poses(truth.stamps_ns, moved, truth.quats))
    return write_bag(tmp_path / f"{name}.bag", records, fmt="rosbag1")


@pytest.fixture
def template(tmp_path: Path) -> Path:
    """A template: /gt against /est named AMCL, nearest association, a tolerance."""
    path = tmp_path / "template.json"
    path.write_text(
        json.dumps(
            {
                "reference": {"selector": "/gt"},
                "estimates": [{"selector": "/est", "name": "AMCL"}],
                "options": {"association": "nearest", "max_dt_s": 0.005, "tolerance": "0.10@95"},
            }
        )
    )
    return path


@pytest.mark.pdf
def test_report_writes_the_summary_with_each_recordings_figures(
    tmp_path: Path, rng, template: Path, capsys
):
    """Each recording is evaluated as `evaluate` would; failures are listed, not fatal."""
    bags = [_bag(tmp_path, rng, f"run{k}", noise=0.02 * (k + 1)) for k in range(2)]
    bags.append(_bag(tmp_path, rng, "gt-only", noise=0, with_estimate=False))
    out = tmp_path / "weekly"
    argv = ["report", "--datasets", *map(str, bags), "--template", str(template)]
    assert main([*argv, "--out", str(out), "--title", "Level 2"]) == 0
    printed = capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["summary.html", "summary.pdf"]
    html = (out / "summary.html").read_text()
    assert "Level 2" in html
    assert "gt-only.bag: failed" in printed
    for bag in bags[:2]:
        assert main(["evaluate", f"{bag}@/gt", f"{bag}@/est", "--associate", "nearest",
                     "--max-dt", "0.005", "--json"]) == 0  # fmt: skip
        ate = json.loads(capsys.readouterr().out)["estimates"][0]["ate"]["translation_m"]["rmse"]
        assert f"{ate:.3f}" in html
        assert f"{bag.name}: succeeded, AMCL ATE {ate:.3f} m" in printed


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("{not json", "is not valid"),
        ('{"reference": {"selector": "/gt"}}', "estimates"),
        ('{"reference": {}, "estimates": [{}], "options": {"align": "best"}}', "align"),
    ],
)
@pytest.mark.parametrize("pdf", ["loads", "missing"])
def test_report_with_a_bad_template_exits_1(
    tmp_path: Path, capsys, *, request: pytest.FixtureRequest, content: str, match: str, pdf: str
):
    """A template that is not valid JSON or misses fields exits 1 and names the problem.

    Also where no PDF can be made: the user's own input is checked before the machine's.
    """
    if pdf == "missing":
        request.getfixturevalue("no_weasyprint")
    path = tmp_path / "template.json"
    path.write_text(content)
    argv = ["report", "--datasets", "x.bag", "--template", str(path), "--out", str(tmp_path / "o")]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert match in err
    assert "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("formats", ["summary.html", " HTML"])
@pytest.mark.usefixtures("no_weasyprint")
def test_an_html_only_report_runs_without_weasyprint(
    tmp_path: Path, rng, template: Path, formats: str
):
    """``--formats summary.html`` lays out no PDF: it writes the HTML where pango is missing."""
    bag = _bag(tmp_path, rng, "run0", noise=0.02)
    out = tmp_path / "weekly"
    argv = ["report", "--datasets", str(bag), "--template", str(template), "--out", str(out)]
    assert main([*argv, "--title", "Level 2", "--formats", formats]) == 0
    assert [p.name for p in out.iterdir()] == ["summary.html"]
    html = (out / "summary.html").read_text()
    assert "Level 2" in html
    assert "run0.bag" in html
    assert "data:image/svg+xml" in html  # the HTML's own plots, not the PDF's PNGs


@pytest.mark.usefixtures("no_weasyprint")
def test_the_default_report_without_weasyprint_exits_1_naming_the_html_only_way(
    tmp_path: Path, rng, template: Path, capsys, *, html_only_templates: Path, monkeypatch
):
    """HTML templates of one's own, both files: without pango it stops before evaluating.

    (The repository's templates need no WeasyPrint: test_pdf_without_weasyprint.py.)
    """
    monkeypatch.setenv("LOCEVAL_TEMPLATES_DIR", str(html_only_templates))
    bag = _bag(tmp_path, rng, "run0", noise=0.02)
    out = tmp_path / "weekly"
    argv = ["report", "--datasets", str(bag), "--template", str(template), "--out", str(out)]
    assert main(argv) == 1
    captured = capsys.readouterr()
    assert "pango" in captured.err
    assert "--formats summary.html" in captured.err
    assert "Traceback" not in captured.err
    assert "run0.bag" not in captured.out  # nothing was evaluated
    assert not out.exists()


def test_report_with_an_unknown_format_exits_1_naming_the_choices(
    tmp_path: Path, template: Path, capsys
):
    """An unknown name in --formats exits 1 naming the valid ones, as ``evaluate`` does."""
    out = tmp_path / "o"
    argv = ["report", "--datasets", "x.bag", "--template", str(template), "--out", str(out)]
    assert main([*argv, "--formats", "summary.html,summary.docx"]) == 1
    err = capsys.readouterr().err
    assert "--formats" in err
    assert "'summary.docx'" in err
    assert "summary.html, summary.pdf" in err
    assert "Traceback" not in err
    assert not out.exists()


@pytest.mark.pdf
def test_a_pdf_only_report_writes_only_the_pdf(tmp_path: Path, rng, template: Path):
    """``--formats summary.pdf`` writes the PDF alone."""
    bag = _bag(tmp_path, rng, "run0", noise=0.02)
    out = tmp_path / "weekly"
    argv = ["report", "--datasets", str(bag), "--template", str(template), "--out", str(out)]
    assert main([*argv, "--formats", "summary.pdf"]) == 0
    assert [p.name for p in out.iterdir()] == ["summary.pdf"]
    assert (out / "summary.pdf").read_bytes().startswith(b"%PDF")
