"""Benchmark: the interactive viewer, from evaluation to a drawn first frame in Chromium.

Run by hand:

    .venv/bin/python -m benchmarks.viewer [--reference-poses 1000000] [--estimate-poses 200000]

For fr2_desk (ORB-SLAM against its motion-capture truth, when the public recordings are in
``$LOCEVAL_PUBLIC_DATA`` or ``../shared/data/public``) and for a synthetic recording of
``--reference-poses`` / ``--estimate-poses`` (two estimates, :func:`benchmarks.report.build`),
it prints, each best of ``--repeat``:

- the time ``export_viewer_html`` adds to an evaluation (the artifact's rendering),
- the size of ``viewer.html``,
- the time from opening ``viewer.html`` from disk in headless Chromium (the system
  ``/usr/bin/chromium``, WebGL on SwiftShader: no GPU) to ``data-ready="true"`` on the
  viewer's root (the first frame with every path drawn).

Targets: data-ready under 1.5 s for fr2_desk and under 5 s for 1,000,000 / 200,000 poses,
viewer.html under 10 MB for the large case.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from benchmarks.report import best_of, build
from exporters.options import ExportOptions
from exporters.viewer import export_viewer_html
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.readers import read_trajectory
from loceval.registration.alignment import AlignMethod

CHROMIUM = "/usr/bin/chromium"
ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--no-first-run",
    "--disable-component-update",
    "--disable-sync",
]


def fr2_desk() -> EvaluationResult | None:
    """ORB-SLAM against fr2_desk's truth (Sim(3)), or None without the public recordings."""
    folder = Path(
        os.environ.get(
            "LOCEVAL_PUBLIC_DATA", Path(__file__).resolve().parents[2] / "shared/data/public"
        )
    )
    if not (folder / "fr2_desk_groundtruth.txt").is_file():
        return None
    ref = read_trajectory(str(folder / "fr2_desk_groundtruth.txt"))
    est = read_trajectory(str(folder / "fr2_desk_ORB.txt"))
    return evaluate(ref, [est], EvaluationConfig(align=AlignMethod.SIM3))


def time_to_ready(path: Path, repeat: int) -> float:
    """Best wall time from opening ``path`` in a fresh page to ``data-ready="true"``."""
    from playwright.sync_api import sync_playwright  # noqa: PLC0415  (a dev dependency)

    best = float("inf")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        for _ in range(repeat):
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            start = time.perf_counter()
            page.goto(path.as_uri())
            page.wait_for_selector(".loceval-viewer[data-ready='true']", timeout=120_000)
            best = min(best, time.perf_counter() - start)
            page.close()
        browser.close()
    return best


def measure(label: str, result: EvaluationResult, repeat: int, folder: Path) -> None:
    """Print the artifact's rendering time, its size and the time to data-ready."""
    options = ExportOptions(title=label)
    seconds, data = best_of(repeat, lambda: export_viewer_html(result, options))
    if not isinstance(data, bytes):
        msg = "export_viewer_html returned no bytes"
        raise TypeError(msg)
    path = folder / f"{label.replace(' ', '_').replace('/', '_')}.html"
    path.write_bytes(data)
    ready = time_to_ready(path, repeat)
    poses = " / ".join(
        f"{n:,}" for n in (len(result.reference), *(len(e.association) for e in result.estimates))
    )
    print(
        f"{label:28s} poses {poses:28s} export {seconds:6.2f} s  "
        f"viewer.html {len(data) / 1e6:6.2f} MB  data-ready {ready:6.2f} s"
    )


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference-poses", type=int, default=1_000_000)
    parser.add_argument("--estimate-poses", type=int, default=200_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        small = fr2_desk()
        if small is None:
            print("fr2_desk: public recordings not found (set LOCEVAL_PUBLIC_DATA); skipped")
        else:
            measure("fr2_desk", small, args.repeat, folder)
        start = time.perf_counter()
        large = build(args.reference_poses, args.estimate_poses)
        print(f"(synthetic evaluation built in {time.perf_counter() - start:.1f} s, not counted)")
        label = f"synthetic {args.reference_poses:,}/{args.estimate_poses:,}"
        measure(label, large, args.repeat, folder)


if __name__ == "__main__":
    main()
