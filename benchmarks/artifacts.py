"""Issues 25 and 43's table: whole-process times of the artifacts, against a baseline and evo.

Run by hand (the public data named in docs/development.md; evo in a scratch environment):

    .venv/bin/python -m benchmarks.artifacts --data ../shared/data/public \\
        [--baseline /tmp/base75] [--evo /work/evo-venv/bin] [--repeat 5] [--service]

Each row runs its command ``--repeat`` times and prints the median wall time and the median
CPU time (user + system of the process and its children: the steadier figure on a shared
machine). With ``--baseline DIR`` (a checkout of another commit, e.g.
``git worktree add /tmp/base75 75865b6``) every command also runs from that checkout, with
the same interpreter and packages (``PYTHONPATH=DIR python -m service.cli``), interleaved
with this tree's run, so both see the same load. The rows:

- fr2_desk (21k reference / 2.9k estimate poses) ``evaluate --align sim3 --out DIR``: the
  default artifact set; then ``--formats report.pdf`` and ``--formats report.html`` alone;
- 200,000 / 50,000 generated TUM poses (:func:`benchmarks.core.write_pair`) ``--out DIR``
  and ``--json``; with ``--evo`` also ``evo_ape tum REF EST -a`` + ``evo_rpe ... -a``;
- with ``--evo``, fr2_desk's whole set against ``evo_ape ... -as --save_plot`` +
  ``evo_rpe ... -as --save_plot`` (two one-page PDFs);
- with ``--service``, ``loceval serve`` on a scratch data folder: from ``POST
  /evaluations`` (fr2_desk, sim3, every artifact) to the result shown by
  ``GET /evaluations/{id}`` and to every artifact, with a warm worker (one evaluation
  first, not counted).

Issue 43's target for the ``200k/50k --json`` row is CPU time: at most a twelfth of evo's
(``python -m benchmarks.artifacts --evo DIR --workdir DIR_OF_THE_PAIR --baseline CHECKOUT``;
to time the row alone: ``PYTHONPATH=$PWD /usr/bin/time -f '%e %U %S' .venv/bin/python -m
service.cli evaluate REF EST --json``). On the two vCPUs of the test machines threads bought
wall time with CPU time (the 21 MB reference parsed in two threads: 0.14 s wall and 0.235 s
CPU; on one: 0.19 s and 0.19 s), so tables under 64 MiB and error series under 200,000 are
handled on one thread. Measured on 2026-11-29 against ca96e43 (load 1.6 to 3.3): 0.744 s ->
0.560 s CPU, evo 7.04 s, 12.6x (12.8x wall); 21 interleaved runs of the row alone: 0.795 s
-> 0.576 s median CPU.

Multi-core machines: the artifacts are written one after another in one process (one
core's throughput, as the two vCPUs of the test machines give); on more cores the CAD
files and the PDF layout could run in parallel processes, which these figures do not count.
"""

from __future__ import annotations

import argparse
import functools
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import httpx2 as httpx

from benchmarks.core import write_pair
from benchmarks.upload_load import create_key, running_server

FR2 = ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt")
TARGETS = {
    "fr2_desk all": 2.0,
    "fr2_desk report.pdf": 1.0,
    "fr2_desk report.html": 0.6,
    "200k/50k --out": 4.0,
}
"""The issue's targets, seconds on a quiet machine."""


def timed(
    argv: Sequence[str], env: dict[str, str] | None = None, cwd: Path | None = None
) -> tuple[float, float]:
    """Run one process; return its wall time and CPU time (with its children's)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(argv, capture_output=True, check=True, env=env, cwd=cwd)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def cli(tree: Path | None) -> tuple[list[str], dict[str, str], Path]:
    """Return the command prefix, environment and folder to run ``loceval`` from ``tree``.

    ``python -m`` puts the working folder first on the import path, before
    ``PYTHONPATH``: each tree's command runs in that tree (None: this checkout).
    """
    env = dict(os.environ)
    folder = Path(__file__).resolve().parents[1] if tree is None else tree
    env["PYTHONPATH"] = str(folder)
    return [sys.executable, "-m", "service.cli"], env, folder


def compile_tree(tree: Path | None) -> None:
    """Write the bytecode of a tree's packages before anything is timed.

    An installed package comes compiled; a checkout is compiled by its first run, unless
    ``PYTHONDONTWRITEBYTECODE`` is set (as on some CI and sandbox machines), in which case
    every run would compile every module again: 0.1-0.3 s of each figure measured here.
    """
    folder = Path(__file__).resolve().parents[1] if tree is None else tree
    packages = [str(folder / name) for name in ("loceval", "exporters", "service")]
    subprocess.run([sys.executable, "-m", "compileall", "-q", *packages], check=True)


def row(
    label: str,
    runs: dict[str, Callable[[], tuple[float, float]]],
    repeat: int,
) -> dict[str, tuple[float, float]]:
    """Run each command ``repeat`` times, interleaved; print and return the medians."""
    walls: dict[str, list[float]] = {name: [] for name in runs}
    cpus: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(repeat):
        for name, run in runs.items():
            wall, cpu = run()
            walls[name].append(wall)
            cpus[name].append(cpu)
    medians = {
        name: (statistics.median(walls[name]), statistics.median(cpus[name])) for name in runs
    }
    figures = "  ".join(
        f"{name}: {wall:6.3f} s wall {cpu:6.3f} s cpu" for name, (wall, cpu) in medians.items()
    )
    target = TARGETS.get(label)
    print(f"{label:24s} {figures}" + (f"  (target < {target:g} s)" if target else ""))
    return medians


def evaluate_runs(
    trees: dict[str, Path | None], args: list[str], out: Path
) -> dict[str, Callable[[], tuple[float, float]]]:
    """Return one ``loceval evaluate ARGS`` run per tree (``--out`` into a scratch folder)."""
    runs: dict[str, Callable[[], tuple[float, float]]] = {}
    for name, tree in trees.items():
        prefix, env, folder = cli(tree)
        argv = [*prefix, "evaluate", *args]
        if "--json" not in args:
            argv += ["--out", str(out / name)]
        runs[name] = functools.partial(timed, argv, env, folder)
        print(f"  {name}: (cd {folder} && PYTHONPATH={folder} {' '.join(argv)})")
    return runs


def evo_run(
    evo: Path, ref: Path, est: Path, flags: Sequence[str], plots: Path | None = None
) -> Callable[[], tuple[float, float]]:
    """Return a run of ``evo_ape`` and then ``evo_rpe`` on the pair (summed times).

    With ``plots``, each tool also saves its plot there (``--save_plot``: a one-page PDF).
    """
    argvs = []
    for tool in ("evo_ape", "evo_rpe"):
        argv = [str(evo / tool), "tum", str(ref), str(est), *flags]
        if plots is not None:
            argv += ["--save_plot", str(plots / f"{tool}.pdf")]
        argvs.append(argv)
        print(f"  evo: {' '.join(argv)}")

    def run() -> tuple[float, float]:
        wall = cpu = 0.0
        for argv in argvs:
            if plots is not None:  # evo asks before it overwrites a plot
                Path(argv[-1]).unlink(missing_ok=True)
            one = timed(argv)
            wall, cpu = wall + one[0], cpu + one[1]
        return wall, cpu

    return run


def service_times(data: Path, repeat: int, scratch: Path, trees: dict[str, Path | None]) -> None:
    """Time POST /evaluations to the result and to every artifact, with a warm worker.

    Each tree's service runs in turn (``PYTHONPATH`` names a baseline checkout).
    """
    print(f"  service: POST /api/v1/evaluations fr2_desk sim3 (all artifacts), {repeat} runs")
    for name, tree in trees.items():
        saved = os.environ.get("PYTHONPATH")
        if tree is not None:
            os.environ["PYTHONPATH"] = str(tree)
        try:
            shown, every = _service_runs(data, repeat, scratch / f"service-{name}")
        finally:
            if saved is None:
                os.environ.pop("PYTHONPATH", None)
            else:
                os.environ["PYTHONPATH"] = saved
        print(
            f"{'service: page figures':24s} {name}: {statistics.median(shown):6.3f} s "
            "(the result document the page draws from; target < 1.5 s)\n"
            f"{'service: to every file':24s} {name}: {statistics.median(every):6.3f} s "
            "(target < 2 s)"
        )


def _service_runs(data: Path, repeat: int, folder: Path) -> tuple[list[float], list[float]]:
    """Start a service in ``folder``; return the times to the result and to every file."""
    folder.mkdir(parents=True)
    with running_server(folder / "data", folder / "service.log") as server:
        key = create_key(server)
        headers = {"Authorization": f"Bearer {key}"}
        with httpx.Client(base_url=server.url, headers=headers, timeout=120.0) as http:
            ids = []
            for name in FR2:
                with (data / name).open("rb") as fh:
                    answer = http.post("/api/v1/datasets", files={"file": (name, fh)})
                answer.raise_for_status()
                ids.append(answer.json()["id"])
            body = {
                "reference": {"dataset_id": ids[0]},
                "estimates": [{"dataset_id": ids[1]}],
                "options": {"align": "sim3"},
            }
            first, every = [], []
            for k in range(repeat + 1):  # the first warms the worker up
                start = time.perf_counter()
                posted = http.post("/api/v1/evaluations", json=body).json()
                url = f"/api/v1/evaluations/{posted['id']}"
                shown = None
                while True:
                    evaluation = http.get(url).json()
                    if shown is None and evaluation["result"] is not None:
                        shown = time.perf_counter() - start
                    if evaluation["status"] in {"succeeded", "failed"}:
                        break
                    time.sleep(0.02)
                done = time.perf_counter() - start
                if evaluation["status"] != "succeeded":
                    msg = f"the evaluation failed: {evaluation['error']}"
                    raise RuntimeError(msg)
                if k:
                    first.append(done if shown is None else shown)
                    every.append(done)
    return first, every


def main() -> int:
    """Measure every row; print the commands with the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("../shared/data/public"))
    parser.add_argument("--baseline", type=Path, help="a checkout to compare with")
    parser.add_argument("--evo", type=Path, help="folder of evo_ape and evo_rpe")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--workdir", type=Path, default=Path("benchmarks/_work"))
    parser.add_argument("--service", action="store_true", help="time the service too")
    parser.add_argument("--skip-large", action="store_true", help="leave out 200k/50k")
    opts = parser.parse_args()
    trees: dict[str, Path | None] = {"new": None}
    if opts.baseline is not None:
        trees = {"old": opts.baseline.resolve(), "new": None}
    opts.data, opts.workdir = opts.data.resolve(), opts.workdir.resolve()
    for tree in trees.values():
        compile_tree(tree)
    ref, est = (opts.data / name for name in FR2)
    opts.workdir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as scratch_name:
        scratch = Path(scratch_name)
        fr2 = [str(ref), str(est), "--align", "sim3"]
        everything = evaluate_runs(trees, fr2, scratch / "all")
        row("fr2_desk all", everything, opts.repeat)
        for fmt in ("report.pdf", "report.html"):
            runs = evaluate_runs(trees, [*fr2, "--formats", fmt], scratch / fmt)
            row(f"fr2_desk {fmt}", runs, opts.repeat)
        if opts.evo is not None:
            (scratch / "evo").mkdir()
            plots = evo_run(opts.evo, ref, est, ["-as"], scratch / "evo")
            medians = row("fr2_desk all vs evo", {**everything, "evo": plots}, opts.repeat)
            wall = medians["new"][0] / medians["evo"][0]
            cpu = medians["new"][1] / medians["evo"][1]
            print(f"{'':24s} new / evo = {cpu:.2f}x CPU, {wall:.2f}x wall (target <= 0.5x CPU)")
        if not opts.skip_large:
            big_ref, big_est = write_pair(opts.workdir, 200_000, 50_000)
            big = [str(big_ref), str(big_est)]
            row("200k/50k --out", evaluate_runs(trees, big, scratch / "big"), opts.repeat)
            json_runs = evaluate_runs(trees, [*big, "--json"], scratch / "json")
            if opts.evo is not None:
                json_runs["evo"] = evo_run(opts.evo, big_ref, big_est, ["-a"])
            medians = row("200k/50k --json", json_runs, opts.repeat)
            if "evo" in medians:
                wall = medians["evo"][0] / medians["new"][0]
                cpu = medians["evo"][1] / medians["new"][1]
                print(f"{'':24s} evo / new = {wall:.1f}x wall, {cpu:.1f}x CPU (target >= 12x)")
        if opts.service:
            service_times(opts.data, opts.repeat, scratch, trees)
    return 0


if __name__ == "__main__":
    sys.exit(main())
