"""Artifacts of an evaluation against control points: errors.csv, report, DXF layers."""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import ezdxf
import numpy as np
import pytest

from exporters.checkpoints import (
    CHECKPOINT_ARTIFACTS,
    checkpoint_errors_csv,
    write_checkpoint_artifacts,
)
from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units
from exporters.plots.checkpoints import error_vector_scale
from loceval.checkpoint_evaluation import (
    CheckpointConfig,
    CheckpointEvaluation,
    evaluate_control_points,
)
from loceval.core.geometry import SimilarityTransform
from loceval.evaluation import EvaluationConfig
from loceval.registration.alignment import AlignMethod
from tests.checkpoint_factory import grid_points, stop_and_go


@pytest.fixture
def evaluation(rng: np.random.Generator) -> CheckpointEvaluation:
    """A 3 x 4 grid at 30 cm visited twice; 3 mm noise, (10, -20, 5) mm bias; auto visits."""
    rec = stop_and_go(rng, grid_points(3, 4), passes=2)
    return evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(),
        reference_name="survey",
    )


def test_errors_csv_has_one_row_per_visit(evaluation: CheckpointEvaluation) -> None:
    """errors.csv: a row per visit with the visit's figures, in time order."""
    rows = list(csv.DictReader(io.StringIO(checkpoint_errors_csv(evaluation).decode())))
    visits = evaluation.estimates[0].result.visits
    assert len(rows) == len(visits) == 24
    for row, visit in zip(rows, visits, strict=True):
        assert row["id"] == visit.point_id
        assert float(row["error_m"]) == visit.error_m
        assert float(row["error_v_m"]) == visit.error_v_m
        assert float(row["x_m"]) == visit.measured_xyz[0]
        assert row["used_for_alignment"] == "false"


def test_arrow_scale() -> None:
    """The largest error spans at most a third of the spacing, at a 1-2-5 scale."""
    rng = np.random.default_rng(3)
    rec = stop_and_go(rng, grid_points(3, 4), passes=1, noise_m=0.0, bias_xyz=(0.015, 0.0, 0.0))
    evaluation = evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(),
    )
    # 0.3 m / 3 / 0.015 m = 6.7 (the stops' medians are within 1 mm of the bias): step 5.
    assert error_vector_scale(evaluation) == pytest.approx(5.0)


def test_report_and_dxf(evaluation: CheckpointEvaluation, tmp_path: Path) -> None:
    """Every artifact is written; the report and the DXF carry the points and the errors."""
    options = ExportOptions(
        units=Units.MM,
        site=SimilarityTransform.identity(),
        evaluation_id="ev1",
        title="survey vs est",
    )
    written = write_checkpoint_artifacts(evaluation, tmp_path / "out", options)
    assert [p.name for p in written] == list(CHECKPOINT_ARTIFACTS)
    html = (tmp_path / "out" / "report.html").read_text()
    entry = evaluation.estimates[0].result.to_dict()["checkpoints"]
    assert "Control-point evaluation report" in html
    assert re.search(r"arrows x\d", html)
    assert f"{entry['score']['hilti']:.1f} %" in html  # type: ignore[index]
    assert len(re.findall(r'<th scope="row">P\d\d</th>', html)) == 12  # a row per point
    assert (tmp_path / "out" / "report.pdf").read_bytes().startswith(b"%PDF")
    doc = ezdxf.readfile(tmp_path / "out" / "paths.dxf")
    layers = {layer.dxf.name for layer in doc.layers}
    assert {"control points", "est measured", "est errors"} <= layers
    msp = doc.modelspace()
    lines = msp.query('LINE[layer=="est errors"]')
    visits = evaluation.estimates[0].result.visits
    assert len(lines) == len(visits)
    first = lines[0]
    np.testing.assert_allclose(tuple(first.dxf.start), np.array(visits[0].surveyed_xyz) * 1000)
    np.testing.assert_allclose(tuple(first.dxf.end), np.array(visits[0].measured_xyz) * 1000)
    labels = [t.dxf.text for t in msp.query('TEXT[layer=="est errors"]')]
    assert labels[0] == f"{visits[0].point_id} {visits[0].error_m * 1000:.1f} mm"
    assert len(msp.query('TEXT[layer=="control points"]')) == 12


def test_ifc_is_refused(evaluation: CheckpointEvaluation, tmp_path: Path) -> None:
    """An IFC of control points is not written: the error names what is."""
    with pytest.raises(ExportOptionsError, match=r"writes result.json, .*not 'paths.ifc'"):
        write_checkpoint_artifacts(
            evaluation, tmp_path / "out", ExportOptions(), names=["paths.glb", "paths.ifc"]
        )
    assert not (tmp_path / "out").exists()
