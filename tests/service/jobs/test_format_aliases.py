"""Output formats are named by file name or by format (dxf, pdf, glb) on both front doors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli import main
from service.schemas.evaluations import EvaluationOptions
from tests.factories import make_trajectory, write_tum


def test_api_options_store_file_names_for_aliases() -> None:
    """``dxf``, ``PDF`` and ``.glb`` become paths.dxf, report.pdf and paths.glb, once each."""
    options = EvaluationOptions.model_validate({"formats": ["dxf", "PDF", ".glb", "paths.dxf"]})
    assert options.formats == ["paths.dxf", "report.pdf", "paths.glb"]


def test_api_rejects_an_unknown_format_naming_the_choices() -> None:
    """An unknown name lists the file names and the format aliases."""
    with pytest.raises(ValueError, match=r"unknown artifact 'docx'; choose from result\.json.*dxf"):
        EvaluationOptions.model_validate({"formats": ["docx"]})


def test_cli_writes_the_formats_named_by_alias(
    tmp_path: Path, rng, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--formats json,csv`` writes result.json and errors.csv, nothing else."""
    truth = make_trajectory(rng, 300)
    ref = write_tum(tmp_path / "ref.txt", truth)
    est = write_tum(tmp_path / "est.txt", truth)
    out = tmp_path / "out"
    code = main(["evaluate", str(ref), str(est), "--formats", "json,csv", "--out", str(out)])
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["errors.csv", "result.json"]
    assert json.loads((out / "result.json").read_text())["estimates"]
    capsys.readouterr()


def test_cli_names_an_unknown_format(tmp_path: Path, rng, capsys: pytest.CaptureFixture[str]):
    """An unknown format exits 1 naming --formats and the choices."""
    truth = make_trajectory(rng, 300)
    ref = write_tum(tmp_path / "ref.txt", truth)
    code = main(["evaluate", str(ref), str(ref), "--formats", "docx", "--out", str(tmp_path / "o")])
    assert code == 1
    err = capsys.readouterr().err
    assert "--formats" in err
    assert "No output format named 'docx'" in err
