"""Benchmark: render the report (HTML, PDF) and errors.csv for a large evaluation.

Run by hand:

    .venv/bin/python -m benchmarks.report [--reference-poses 1000000] [--estimate-poses 200000]

Builds a synthetic recording with :func:`loceval.evaluation.evaluate`: a reference of
``--reference-poses`` poses at 100 Hz (a walk looping through two rooms, with a few
tracking-loss gaps) and two estimates of ``--estimate-poses`` poses each (noise, drift, a
rigid frame change), with a 0.10@95 tolerance. It then times, each best of ``--repeat``:

- the plots (drawn once, shared by HTML and PDF),
- ``render_report_html`` and ``render_report_pdf`` (the ARTIFACTS exporters, each drawing
  its own plots),
- ``render_report`` (HTML and PDF with one set of plots),
- ``export_errors_csv``,

and prints the sizes of the files. Targets: every artifact in seconds, the HTML under a
few MB (plots are decimated for drawing; statistics use every pose).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from exporters.options import ExportOptions
from exporters.plots import render_plots
from exporters.report import render_report, render_report_html, render_report_pdf
from exporters.tables import export_errors_csv
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.trajectory import Trajectory

RATE_HZ = 100.0
LAP_S = 60.0


def make_reference(n: int) -> Trajectory:
    """A walk around two rooms at 100 Hz, one lap a minute, with three tracking losses."""
    t = np.arange(n) / RATE_HZ
    s = t / LAP_S * 2 * np.pi
    x = 4.0 * np.cos(s) + 1.5 * np.cos(3 * s)
    y = 3.0 * np.sin(s)
    z = 1.3 + 0.1 * np.sin(5 * s)
    yaw = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    quat = Rotation.from_euler("z", yaw[:, None]).as_quat()
    keep = np.ones(n, dtype=bool)
    for frac in (0.2, 0.5, 0.8):  # 2 s of tracking loss each
        a = int(frac * n)
        keep[a : a + int(2 * RATE_HZ)] = False
    stamps = (1_700_000_000 * 10**9 + np.rint(t * 1e9)).astype(np.int64)
    return Trajectory(
        stamps[keep], np.stack([x, y, z], 1)[keep], quat[keep], name="OptiTrack", source="gt"
    )


def make_estimate(
    rng: np.random.Generator, reference: Trajectory, m: int, *, sigma: float, name: str
) -> Trajectory:
    """``m`` poses spread over the reference's time with noise, drift and a frame change."""
    t_ns = np.linspace(reference.stamps_ns[0], reference.stamps_ns[-1], m).astype(np.int64)
    idx = np.clip(np.searchsorted(reference.stamps_ns, t_ns), 0, len(reference) - 1)
    idx = np.unique(idx)
    sel = reference.select(idx)
    k = np.arange(len(sel))[:, None] / len(sel)
    pos = sel.positions_xyz + rng.normal(0, sigma, (len(sel), 3)) + 0.2 * np.sin(6 * k)
    frame = Rotation.from_euler("z", 30, degrees=True)
    if sel.quat_xyzw is None:
        msg = "The synthetic reference has orientations."
        raise RuntimeError(msg)
    quat = (frame * Rotation.from_quat(sel.quat_xyzw)).as_quat()
    shift = np.array([2.0, -1.0, 0.0])
    return Trajectory(sel.stamps_ns, frame.apply(pos) + shift, quat, name=name)


def best_of(repeat: int, fn: Callable[[], object]) -> tuple[float, object]:
    """Return the best wall time of ``repeat`` calls and the last call's value."""
    best, value = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
    return best, value


def build(n_ref: int, n_est: int) -> EvaluationResult:
    """Evaluate two estimates against the reference."""
    rng = np.random.default_rng(20240601)
    reference = make_reference(n_ref)
    estimates = [
        make_estimate(rng, reference, n_est, sigma=0.02, name="RTAB-Map"),
        make_estimate(rng, reference, n_est, sigma=0.05, name="ISAAC"),
    ]
    return evaluate(reference, estimates, EvaluationConfig(tolerance=Tolerance(0.10, 0.95)))


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference-poses", type=int, default=1_000_000)
    parser.add_argument("--estimate-poses", type=int, default=200_000)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()

    start = time.perf_counter()
    result = build(args.reference_poses, args.estimate_poses)
    matched = [len(e.association) for e in result.estimates]
    print(
        f"evaluation: {len(result.reference):,} reference poses, "
        f"{len(result.estimates)} estimates with {', '.join(f'{m:,}' for m in matched)} "
        f"matched poses ({time.perf_counter() - start:.1f} s to evaluate, not counted)"
    )
    options = ExportOptions(title="Benchmark report")
    rows = [
        ("plots, SVG only (render_plots)", lambda: render_plots(result)),
        ("report.html (render_report_html)", lambda: render_report_html(result, options)),
        ("report.pdf (render_report_pdf)", lambda: render_report_pdf(result, options)),
        (
            "report.html + report.pdf (render_report)",
            lambda: render_report(result, options=options),
        ),
        ("errors.csv (export_errors_csv)", lambda: export_errors_csv(result, options)),
    ]
    for label, fn in rows:
        seconds, value = best_of(args.repeat, fn)
        if isinstance(value, bytes):
            size = f"{len(value) / 1e6:8.2f} MB"
        elif isinstance(value, tuple) and value and isinstance(value[0], bytes):
            size = " + ".join(f"{len(v) / 1e6:.2f} MB" for v in value)
        else:
            size = ""
        print(f"{label:44s} {seconds:7.2f} s  {size}")


if __name__ == "__main__":
    main()
