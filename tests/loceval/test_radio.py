"""The radio pipeline (loceval.radio_evaluation): options, the x-y only measurement, the
evaluation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.options import AlignMethod
from loceval.radio.multilateration import Solver
from loceval.radio_evaluation import RangingConfig, evaluate_radio, parse_solvers, parse_tag_offset
from tests.radio_factory import make_ranges, make_reference


def test_planar_measures_in_x_y_only() -> None:
    """An estimate 1 m above the reference: ATE 1 m, and 0 when measured in x-y only."""
    reference = make_reference(rate_hz=10.0)
    lifted = replace(reference, positions_xyz=reference.positions_xyz + np.array([0.0, 0.0, 1.0]))
    config = EvaluationConfig(align=AlignMethod.NONE)
    full = evaluate(reference, [lifted], config).estimates[0].ate_translation.stats
    flat = evaluate(reference, [lifted], replace(config, planar=True))
    assert full.rmse == pytest.approx(1.0)
    assert flat.estimates[0].ate_translation.stats.rmse == pytest.approx(0.0, abs=1e-12)
    assert flat.to_dict()["options"]["planar"] is True  # type: ignore[index]


def test_evaluate_radio_sets_planar_and_the_ranging_part(rng: np.random.Generator) -> None:
    """2D: estimates nlls then minmax, x-y only; the document's ranging object and options."""
    reference = make_reference()
    ranges = make_ranges(rng, end_s=30.0).ranges
    result = evaluate_radio(reference, ranges, RangingConfig())
    assert [e.name for e in result.estimates] == ["nlls", "minmax"]
    assert result.config.planar
    assert result.ranging is not None
    document = result.to_dict()
    ranging = document["ranging"]
    assert isinstance(ranging, dict)
    assert ranging["options"]["solve"] == ["nlls", "minmax"]
    assert ranging["options"]["tag_height_m"] == pytest.approx(1.2)  # the walk's median height
    assert ranging["dropped"] == {"outside": 0, "gap": 0}
    three_d = evaluate_radio(reference, ranges, RangingConfig(dims=3, solvers=(Solver.MINMAX,)))
    assert not three_d.config.planar
    assert [e.name for e in three_d.estimates] == ["minmax"]


def test_tag_offset_moves_the_reference(rng: np.random.Generator) -> None:
    """With a tag offset the estimates are compared with the tag, not the carrier's origin."""
    offset = (0.5, 0.0, 0.0)
    reference = make_reference()
    ranges = make_ranges(
        rng, end_s=30.0, tag_offset_xyz=offset, noise_m=[0.0] * 13, bias_m=[0.0] * 13,
        synchronous=True,
    ).ranges  # fmt: skip
    moved = evaluate_radio(reference, ranges, RangingConfig(tag_offset_xyz=offset))
    plain = evaluate_radio(reference, ranges, RangingConfig(solvers=(Solver.NLLS,)))
    assert moved.estimates[0].ate_translation.stats.max < 0.01
    # Without the offset the tag is 0.5 m ahead of the origin: the error is about 0.5 m.
    assert plain.estimates[0].ate_translation.stats.median == pytest.approx(0.5, abs=0.01)
    device = EvaluationConfig(reference_offset=SimilarityTransform.identity())
    with pytest.raises(InputError, match=r"tag offset or a device offset") as err:
        evaluate_radio(reference, ranges, RangingConfig(tag_offset_xyz=offset), device)
    assert err.value.option == "tag_offset_xyz"


@pytest.mark.parametrize(
    ("kwargs", "option", "match"),
    [
        ({"dims": 4}, "dims", r"must be 2 or 3, got 4"),
        ({"epoch_s": 0.0}, "epoch_s", r"epoch length must be a finite number of seconds"),
        ({"outlier_threshold_m": -1.0}, "outlier_threshold_m", r"outlier threshold must be"),
        ({"distance_bin_m": float("nan")}, "distance_bin_m", r"distance bin width must be"),
        ({"tag_height_m": 1e9}, "tag_height_m", r"tag height must be .* at most 10000"),
        ({"solvers": ()}, "solve", r"Name each positioning algorithm once"),
    ],
)
def test_bad_ranging_options(kwargs: dict[str, object], option: str, match: str) -> None:
    """Each bad value names its option key (the front doors add the flag or field)."""
    with pytest.raises(InputError, match=match) as err:
        RangingConfig(**kwargs)  # type: ignore[arg-type]
    assert err.value.option == option
    assert "--" not in str(err.value)


def test_parse_solvers_and_tag_offset() -> None:
    """Solver names in order without repeats; offsets as three numbers."""
    assert parse_solvers(["minmax", "nlls", "minmax"]) == (Solver.MINMAX, Solver.NLLS)
    with pytest.raises(InputError, match=r"are nlls and minmax, got 'ekf'") as err:
        parse_solvers(["ekf"])
    assert err.value.suggest == "nlls,minmax"
    assert parse_tag_offset("0.1, 0 0.3") == (0.1, 0.0, 0.3)
    assert parse_tag_offset(None) is None
    assert parse_tag_offset("  ") is None
    with pytest.raises(InputError, match=r'three numbers "x y z" in metres, got \'1 nan 2\''):
        parse_tag_offset("1 nan 2")
