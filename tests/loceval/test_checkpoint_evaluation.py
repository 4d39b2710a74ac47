"""The control-point evaluation document, its options, and how surveys and visits are told."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from loceval.checkpoint_evaluation import CheckpointConfig, evaluate_control_points
from loceval.checkpoints.fit import evaluate_checkpoints
from loceval.errors import InputError, ReaderError
from loceval.evaluation import EvaluationConfig
from loceval.inspection import input_kind, inspect
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory, sniff_format
from loceval.registration.alignment import AlignMethod
from tests.checkpoint_factory import NS, grid_points, stop_and_go, write_points, write_visits


def test_document_keeps_the_json_shape(rng: np.random.Generator) -> None:
    """Top-level keys as a trajectory evaluation's; reference kind control_points."""
    rec = stop_and_go(rng, grid_points(3, 4), passes=1)
    doc = evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(),
        reference_name="survey",
        inputs=[{"role": "reference"}, {"role": "estimate"}],
    ).to_dict()
    assert list(doc) == [
        "loceval_version", "created_at", "options", "inputs", "reference", "estimates",
    ]  # fmt: skip
    assert doc["reference"]["kind"] == "control_points"  # type: ignore[index]
    assert doc["reference"]["points"] == 12  # type: ignore[index]
    assert doc["reference"]["extent_m"] == pytest.approx([0.9, 0.6, 0.0])  # type: ignore[index]
    [entry] = doc["estimates"]  # type: ignore[misc]
    core = evaluate_checkpoints(rec.points, rec.estimate).to_dict()
    assert entry["checkpoints"] == core["checkpoints"]
    assert entry["ate"] == core["ate"]
    assert (entry["name"], entry["poses"]) == ("est", len(rec.estimate))


def test_time_offset_moves_the_estimate(rng: np.random.Generator) -> None:
    """The time offset is added to the estimate's stamps before the visits are matched."""
    rec = stop_and_go(rng, grid_points(3, 4), passes=1)
    late = rec.estimate.shifted(-5 * NS)
    result = evaluate_control_points(
        rec.points,
        [late],
        EvaluationConfig(align=AlignMethod.NONE, time_offset_s=5.0),
        CheckpointConfig(),
    )
    assert result.estimates[0].estimate.stamps_ns[0] == rec.estimate.stamps_ns[0]


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("visit_radius_m", 0.0, "The visit radius"),
        ("stop_speed_mps", -1.0, "The stop speed"),
        ("stop_min_s", float("nan"), "The minimum stop duration"),
    ],
)
def test_config_bounds(field: str, value: float, words: str) -> None:
    """Out-of-bounds values fail with the option's key and neutral words."""
    with pytest.raises(InputError, match=rf"^{words} must be a finite number") as err:
        CheckpointConfig(**{field: value})  # type: ignore[arg-type]
    assert err.value.option == field


def test_survey_and_visits_are_told_by_their_header(tmp_path: Path) -> None:
    """id,x,y,z sniffs as points; id,t_start,t_end inspects as visits; neither is a path."""
    points = grid_points(3, 4)
    survey = write_points(tmp_path / "survey.csv", points)
    assert sniff_format(survey) is TrajectoryFormat.POINTS
    timed = tmp_path / "timed.csv"
    timed.write_text("t,id,x,y,z\n1.0,A,0,0,0\n2.0,B,1,0,0\n")
    assert sniff_format(timed) is TrajectoryFormat.CSV  # a time column: not a survey
    rec = stop_and_go(np.random.default_rng(1), points, passes=1)
    visits = write_visits(tmp_path / "visits.csv", rec)
    assert input_kind(SourceSpec(None, visits)) == "visits"
    info = inspect(visits).to_dict()
    assert (info["visits"], len(info["ids"])) == (12, 12)  # type: ignore[arg-type]
    assert info["start_s"] == pytest.approx(rec.visit_start_ns.min() / NS, abs=1e-6)
    assert inspect(survey).to_dict()["points"] == 12
    with pytest.raises(ReaderError, match=r"holds control points \(id,x,y,z\), not a trajectory"):
        read_trajectory(f"points:{survey}")
    with pytest.raises(ReaderError, match=r"points sources take no selector|no options"):
        read_trajectory(f"points:{survey}@x=1")
