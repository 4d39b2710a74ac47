"""The result document read back: every figure the writers write is read, by its type."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from exporters import ExportOptions, export_result_json
from loceval.checkpoint_evaluation import CheckpointConfig, evaluate_control_points
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, Tolerance, evaluate
from loceval.registration.alignment import AlignMethod
from loceval.results.document import STAT_NAMES, ResultRead, read_result
from tests.checkpoint_factory import grid_points, stop_and_go
from tests.factories import make_trajectory, perturb


def _trajectory_document(rng: np.random.Generator) -> tuple[Any, dict[str, Any]]:
    """A two-estimate evaluation with a tolerance and intervals, and its result.json."""
    truth = replace(make_trajectory(rng, n=400, name="truth"), warnings=("truth: a note",))
    good = replace(perturb(truth, rng, sigma_m=0.01), name="good", warnings=("good: a note",))
    bad = replace(perturb(truth, rng, sigma_m=0.3), name="bad")
    result = evaluate(truth, [good, bad], EvaluationConfig(tolerance=Tolerance.parse("0.1@95")))
    document = json.loads(export_result_json(result, ExportOptions(evaluation_id="ev")))
    return result, document


def _figures(read: ResultRead) -> list[object]:
    """Everything the reader hands out, in a comparable form."""
    return [
        read.kind,
        read.reference_duration_s,
        read.reference_warnings,
        dict(read.section_warnings),
        [
            (
                e.name,
                e.matched,
                None if e.ate_translation is None else dict(e.ate_translation.values),
                None if e.ate_translation is None else e.ate_translation.ci95,
                None if e.ate_translation is None else e.ate_translation.n_effective,
                None if e.rpe_translation is None else dict(e.rpe_translation.values),
                None if e.ate_rotation is None else dict(e.ate_rotation.values),
                None if e.rpe_rotation is None else dict(e.rpe_rotation.values),
                e.verdict,
                e.warnings,
            )
            for e in read.estimates
        ],
    ]


def test_a_trajectory_result_reads_back_as_the_core_wrote_it(rng: np.random.Generator) -> None:
    """Statistics are the core's ErrorStats, the verdicts its outcomes, the warnings its own."""
    result, document = _trajectory_document(rng)
    read = read_result(document)
    assert read.kind == "trajectory"
    assert read.reference_duration_s == pytest.approx(result.reference.duration_s)
    assert [e.name for e in read.estimates] == ["good", "bad"]
    for written, estimate in zip(result.estimates, read.estimates, strict=True):
        assert estimate.matched == len(written.association)
        for block, series in (
            (estimate.ate_translation, written.ate_translation),
            (estimate.rpe_translation, written.rpe_translation),
            (estimate.ate_rotation, written.ate_rotation),
            (estimate.rpe_rotation, written.rpe_rotation),
        ):
            assert block is not None
            assert series is not None
            assert block.stats() == series.stats  # every field, by the type that wrote it
            assert block.ci95 is not None
            assert block.n_effective is not None
        assert written.verdict is not None
        assert estimate.verdict is not None
        assert (estimate.verdict.passed, estimate.verdict.outcome) == (
            written.verdict.passed,
            written.verdict.result,
        )
        assert estimate.warnings == written.warnings
    assert [e.verdict.outcome for e in read.estimates if e.verdict] == ["pass", "fail"]
    assert read.warnings()[:2] == [("reference", "truth: a note"), ("good", "good: a note")]
    assert read.estimates[1].figures_as_written() == {
        key: document["estimates"][1][key] for key in ("ate", "rpe", "verdict")
    }


def test_a_control_point_result_reads_its_ate_and_no_rpe(rng: np.random.Generator) -> None:
    """A control-point estimate has an ATE of the visits and, by its kind, no RPE."""
    rec = stop_and_go(rng, grid_points(3, 4), passes=1)
    evaluation = evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(),
        reference_name="survey",
    )
    read = read_result(json.loads(json.dumps(evaluation.to_dict())))
    assert read.kind == "control_points"
    (estimate,) = read.estimates
    assert estimate.name == "est"
    assert estimate.matched == 12
    assert estimate.ate_translation is not None
    assert estimate.ate_translation.n == 12
    assert estimate.rpe_translation is None
    assert estimate.verdict is None


# Every place of the document the reader reads: renaming any of these keys in the writer must
# change what is read (so a round trip above fails), never be read as if nothing had changed.
_READ_KEYS = [
    ("reference", "duration_s"),
    ("reference", "warnings"),
    ("estimates", 0, "name"),
    ("estimates", 0, "matched"),
    ("estimates", 0, "ate"),
    ("estimates", 0, "ate", "translation_m"),
    ("estimates", 0, "ate", "rotation_deg"),
    ("estimates", 0, "ate", "translation_m", "ci95"),
    ("estimates", 0, "ate", "translation_m", "n_effective"),
    ("estimates", 0, "rpe"),
    ("estimates", 0, "rpe", "translation_m"),
    ("estimates", 0, "rpe", "rotation_deg"),
    ("estimates", 0, "verdict"),
    ("estimates", 0, "verdict", "passed"),
    ("estimates", 0, "verdict", "outcome"),
    ("estimates", 0, "warnings"),
    *[("estimates", 0, "ate", "translation_m", name) for name in STAT_NAMES],
]


@pytest.mark.parametrize("path", _READ_KEYS, ids=lambda p: ".".join(map(str, p)))
def test_a_renamed_key_changes_what_is_read(rng: np.random.Generator, path: tuple) -> None:
    """A key the writer renamed is noticed: the read differs (no figure silently the same)."""
    _, document = _trajectory_document(rng)
    before = _figures(read_result(document))
    renamed = copy.deepcopy(document)
    parent: Any = renamed
    for key in path[:-1]:
        parent = parent[key]
    parent[f"{path[-1]}_renamed"] = parent.pop(path[-1])
    try:
        after = _figures(read_result(renamed))
    except InputError:
        return  # refused outright: as good as a changed figure
    assert after != before


def test_what_is_no_result_document_is_refused() -> None:
    """No estimates list, or an estimate that is not an object, is not read as empty."""
    with pytest.raises(match="no 'estimates' list"):
        read_result({"reference": {}})
    with pytest.raises(match="no 'estimates' list"):
        read_result(["estimates"])
    with pytest.raises(match=r"estimates\[1\] .* not an object"):
        read_result({"estimates": [{}, "oops"]})


def test_documents_before_the_intervals_are_read() -> None:
    """No ci95, a verdict with only ``passed``, NaN written as null: read as absent."""
    document = {
        "reference": {"duration_s": 12.5},
        "estimates": [
            {
                "name": "",
                "matched": 10,
                "ate": {"translation_m": {"rmse": 0.1, "n": 10}},
                "rpe": {"translation_m": {"rmse": None}},
                "verdict": {"passed": True},
            }
        ],
    }
    (estimate,) = read_result(document).estimates
    assert estimate.label == "estimate 1"
    assert estimate.ate_translation is not None
    assert (estimate.ate_translation.rmse, estimate.ate_translation.n) == (0.1, 10)
    assert estimate.ate_translation.stats() is None  # incomplete: not an ErrorStats
    assert estimate.ate_translation.ci95 is None
    assert estimate.rpe_translation is not None
    assert estimate.rpe_translation.rmse is None
    assert estimate.verdict is not None
    assert (estimate.verdict.passed, estimate.verdict.outcome) == (True, "pass")
