"""errors.csv: every matched pose with reference, aligned estimate, ATE and RPE."""

from __future__ import annotations

import csv
import io
from decimal import Decimal

import numpy as np
import pytest

from exporters import ARTIFACTS, tables
from exporters.options import ExportOptions
from exporters.tables import ERRORS_CSV_COLUMNS, errors_csv_chunks, export_errors_csv
from loceval.evaluation import EvaluationResult, evaluate
from tests.exporters.conftest import noisy, walk


def _read(data: bytes) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(data.decode("utf-8"))))


@pytest.fixture
def rows(two_estimates: EvaluationResult) -> list[dict[str, str]]:
    """Return errors.csv of the two-estimate evaluation, parsed."""
    return _read(export_errors_csv(two_estimates, ExportOptions()))


def test_header_and_one_row_per_matched_pose(
    two_estimates: EvaluationResult, rows: list[dict[str, str]]
) -> None:
    """The header is the documented one and every matched pose of every estimate has a row."""
    data = export_errors_csv(two_estimates, ExportOptions())
    assert data.splitlines()[0].decode() == ",".join(ERRORS_CSV_COLUMNS)
    assert data.endswith(b"\n")
    assert len(rows) == sum(len(e.association) for e in two_estimates.estimates)
    names = [r["estimate"] for r in rows]
    assert names == [e.name for e in two_estimates.estimates for _ in range(len(e.association))]


def test_values_match_the_result(
    two_estimates: EvaluationResult, rows: list[dict[str, str]]
) -> None:
    """Positions, ATE and RPE round-trip to the result's arrays within the printed precision."""
    start = 0
    for e in two_estimates.estimates:
        n = len(e.association)
        block = rows[start : start + n]
        start += n
        table = np.array(
            [[float(r[c]) for c in ERRORS_CSV_COLUMNS[3:11]] for r in block], dtype=np.float64
        )
        np.testing.assert_allclose(table[:, 0:3], e.association.reference.positions_xyz, atol=5e-7)
        np.testing.assert_allclose(table[:, 3:6], e.aligned.positions_xyz, atol=5e-7)
        np.testing.assert_allclose(table[:, 6], e.ate_translation.values, atol=5e-7)
        assert e.ate_rotation is not None
        np.testing.assert_allclose(table[:, 7], e.ate_rotation.values, atol=5e-7)
        stamps = [int(r["stamp_ns"]) for r in block]
        assert stamps == e.association.reference.stamps_ns.tolist()
        # RPE sits on the pose that starts each pair; the last pose starts none.
        starts = e.rpe_index[:, 0]
        rpe = np.array([float(r["rpe_m"]) if r["rpe_m"] else np.nan for r in block])
        np.testing.assert_allclose(rpe[starts], e.rpe_translation.values, atol=5e-7)
        assert np.isnan(np.delete(rpe, starts)).all()
        assert block[-1]["rpe_m"] == ""
        assert block[-1]["rpe_deg"] == ""


def test_time_is_exact_seconds_since_the_reference_start(
    two_estimates: EvaluationResult, rows: list[dict[str, str]]
) -> None:
    """t_s is the stamp minus the reference's first stamp, to the nanosecond."""
    t0 = int(two_estimates.reference.stamps_ns[0])
    for r in rows[:50] + rows[-50:]:
        assert Decimal(r["t_s"]) == Decimal(int(r["stamp_ns"]) - t0) / Decimal(10**9)
        assert len(r["t_s"].split(".")[1]) == 9


def test_numbers_are_plain_fixed_point(rows: list[dict[str, str]]) -> None:
    """Floats have six decimals, negatives a single minus sign, no padding or exponent."""
    values = [r[c] for r in rows for c in ("ref_x", "est_y", "ate_m")]
    assert any(v.startswith("-") for v in values)
    for v in values:
        whole, _, frac = v.lstrip("-").partition(".")
        assert whole.isdigit()
        assert len(frac) == 6
        assert frac.isdigit()
        assert whole == "0" or not whole.startswith("0")
        assert v != "-0.000000"


def test_position_only_leaves_rotation_columns_empty(rng: np.random.Generator) -> None:
    """Without orientations ate_deg and rpe_deg are empty cells, not zeros."""
    truth = walk(rng, n=600)
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="UWB").without_orientation()
    rows = _read(export_errors_csv(evaluate(truth, [est]), ExportOptions()))
    assert rows
    assert all(r["ate_deg"] == "" and r["rpe_deg"] == "" for r in rows)
    assert all(r["ate_m"] for r in rows)


def test_names_with_commas_are_quoted(rng: np.random.Generator) -> None:
    """An estimate name with a comma or quote is CSV-quoted and reads back unchanged."""
    truth = walk(rng, n=300)
    name = 'ORB-SLAM3, "mono"'
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name=name)
    rows = _read(export_errors_csv(evaluate(truth, [est]), ExportOptions()))
    assert {r["estimate"] for r in rows} == {name}


def test_chunks_join_to_the_file(two_estimates: EvaluationResult) -> None:
    """Streaming in small pieces yields the same bytes as the whole file."""
    whole = export_errors_csv(two_estimates, ExportOptions())
    pieces = list(errors_csv_chunks(two_estimates, chunk_rows=7))
    assert len(pieces) > 100
    assert b"".join(pieces) == whole


def test_large_values_fall_back_to_exact_text() -> None:
    """Numbers beyond int64 fixed point (1e13 m at six decimals) are still written exactly."""
    values = np.array([1.5e13, -2.25e14, np.nan, 0.125])
    text = tables._rows([tables._float_field(values, 6)]).decode()
    assert text.splitlines() == [
        "15000000000000.000000",
        "-225000000000000.000000",
        "",
        "0.125000",
    ]


def test_fixed_point_matches_python_formatting(rng: np.random.Generator) -> None:
    """The vectorized formatter writes what f"{x:.6f}" writes (except for negative zero)."""
    values = np.concatenate([rng.normal(0, 50, 20_000), rng.normal(0, 1e-5, 1000), [0.0]])
    text = tables._rows([tables._float_field(values, 6)]).decode().splitlines()
    expected = [f"{v:.6f}".replace("-0.000000", "0.000000") for v in values]
    assert text == expected


def test_registry_points_at_this_exporter() -> None:
    """ARTIFACTS names export_errors_csv for errors.csv."""
    assert ARTIFACTS["errors.csv"].load() is export_errors_csv
    assert ARTIFACTS["errors.csv"].media_type == "text/csv"
