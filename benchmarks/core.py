"""Time the whole ``loceval evaluate --json`` process on generated TUM files.

Run by hand: ``.venv/bin/python -m benchmarks.core [--workdir DIR] [--repeat N]
[--case small|large|all] [--breakdown] [--evo BIN]``.

Targets on a 2-core machine (read + associate + align + ATE + RPE, process start included):

- 200,000 reference / 50,000 estimate poses: 0.7 s wall, a tenth of evo's 7.06 s
  (``evo_ape`` + ``evo_rpe`` on the same files, measured side by side on a quiet machine
  for issue 11; evo is not installed here);
- 1,000,000 / 200,000: under 5 s.

Wall time on a shared machine moves with the other users' load, so every row also shows
the process's CPU time (user + system), the steadier figure. ``--breakdown`` times the
phases inside one process: interpreter start, importing the CLI, reading each file and
the evaluation (``python -X importtime -c "import service.cli"`` itemizes the imports).
``--evo BIN`` also times ``BIN/evo_ape tum REF EST -a`` + ``BIN/evo_rpe tum REF EST -a`` on
the small case, alternating with loceval, and prints the ratio: the fair comparison on any
machine. evo is GPL and never a dependency: install it in a scratch virtual environment
(``python3 -m venv /tmp/evo && /tmp/evo/bin/pip install evo``) and pass ``/tmp/evo/bin``.
A figure independent of the load is the instruction count of one run:
``valgrind --tool=callgrind .venv/bin/loceval evaluate REF EST --json`` (about a minute).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from loceval.core.rotation import Rotation

EVO_S = 7.06
"""evo_ape + evo_rpe on the 200,000 / 50,000 files (issue 11)."""
CASES = {"small": (200_000, 50_000, EVO_S / 10.0), "large": (1_000_000, 200_000, 5.0)}

_PHASES = """
import json, sys, time
t0 = time.perf_counter()
import service.cli
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.readers import read_trajectory
t1 = time.perf_counter()
ref = read_trajectory("tum:" + sys.argv[1])
t2 = time.perf_counter()
est = read_trajectory("tum:" + sys.argv[2])
t3 = time.perf_counter()
evaluate(ref, [est], EvaluationConfig())
t4 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "read reference": t2 - t1, "read estimate": t3 - t2,
                  "evaluate": t4 - t3}))
"""


def write_pair(folder: Path, n_ref: int, n_est: int) -> tuple[Path, Path]:
    """Write a reference at 200 Hz and a noisy, rotated estimate sampled from it."""
    ref_path = folder / f"ref_{n_ref}.tum"
    est_path = folder / f"est_{n_ref}_{n_est}.tum"
    if ref_path.exists() and est_path.exists():
        return ref_path, est_path
    rng = np.random.default_rng(7)
    t = 1_700_000_000.0 + np.arange(n_ref) / 200.0
    s = np.linspace(0, 40 * np.pi, n_ref)
    xyz = np.stack([10 * np.cos(s / 7), 6 * np.sin(s / 5), 1.2 + 0.2 * np.sin(s)], 1)
    quat = Rotation.from_euler("z", s[:, None]).as_quat()
    np.savetxt(ref_path, np.column_stack([t, xyz, quat]), fmt="%.9f")
    idx = np.sort(rng.choice(n_ref, n_est, replace=False))
    frame = Rotation.from_euler("z", 25, degrees=True)
    est_xyz = frame.apply(xyz[idx] + rng.normal(0, 0.03, (n_est, 3))) + np.array([1.0, 2.0, 0.0])
    est_quat = (frame * Rotation.from_quat(quat[idx])).as_quat()
    np.savetxt(est_path, np.column_stack([t[idx], est_xyz, est_quat]), fmt="%.9f")
    return ref_path, est_path


def time_run(args: list[str]) -> tuple[float, float]:
    """Return the wall and CPU time of one CLI process, checking its JSON output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    out = subprocess.run(args, capture_output=True, text=True, check=True)
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    json.loads(out.stdout)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return elapsed, cpu


def breakdown(ref: Path, est: Path, repeat: int) -> None:
    """Print the median time of each phase of an evaluation, over ``repeat`` processes."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    start_s = [time_run([sys.executable, "-c", "print('{}')"])[0] for _ in range(repeat)]
    runs = [
        json.loads(
            subprocess.run(
                [sys.executable, "-c", _PHASES, str(ref), str(est)],
                capture_output=True,
                text=True,
                check=True,
                env=env,
            ).stdout
        )
        for _ in range(repeat)
    ]
    print(f"{'interpreter start':>18} {statistics.median(start_s):7.3f} s")
    for phase in runs[0]:
        print(f"{phase:>18} {statistics.median(run[phase] for run in runs):7.3f} s")


def compare_with_evo(evo_bin: Path, cli: str, ref: Path, est: Path, repeat: int) -> None:
    """Time evo_ape + evo_rpe and ``loceval evaluate --json`` in turn; print the ratio."""
    evo_s, ours_s = [], []
    for _ in range(repeat):
        start = time.perf_counter()
        for tool in ("evo_ape", "evo_rpe"):
            subprocess.run(
                [str(evo_bin / tool), "tum", str(ref), str(est), "-a"],
                capture_output=True,
                check=True,
            )
        evo_s.append(time.perf_counter() - start)
        ours_s.append(time_run([cli, "evaluate", str(ref), str(est), "--json"])[0])
    evo, ours = statistics.median(evo_s), statistics.median(ours_s)
    print(f"evo_ape + evo_rpe {evo:.2f} s, loceval {ours:.3f} s: {evo / ours:.1f}x (target 10x)")


def main() -> int:
    """Generate the files, time each case, print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("benchmarks/_work"))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--case", choices=[*CASES, "all"], default="all")
    parser.add_argument("--breakdown", action="store_true", help="time the phases (small case)")
    parser.add_argument("--evo", type=Path, help="folder of evo_ape and evo_rpe: time them too")
    opts = parser.parse_args()
    opts.workdir.mkdir(parents=True, exist_ok=True)
    cli = str(Path(sys.executable).with_name("loceval"))
    print(
        f"{'reference':>10} {'estimate':>9} {'associate':>11} {'median s':>9} {'min s':>7} "
        f"{'cpu s':>6} target"
    )
    for case, (n_ref, n_est, target) in CASES.items():
        if opts.case not in {case, "all"}:
            continue
        ref, est = write_pair(opts.workdir, n_ref, n_est)
        for method in ("interpolate", "nearest"):
            argv = [cli, "evaluate", str(ref), str(est), "--json", "--associate", method]
            runs = [time_run(argv) for _ in range(opts.repeat)]
            med = statistics.median(wall for wall, _ in runs)
            cpu = statistics.median(cpu for _, cpu in runs)
            verdict = "ok" if med < target else "MISSED"
            print(f"{n_ref:>10} {n_est:>9} {method:>11} {med:>9.3f} "
                  f"{min(wall for wall, _ in runs):>7.3f} {cpu:>6.3f} "
                  f"< {target:.2f} s {verdict}")  # fmt: skip
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak RSS of the largest run: {peak_mb:.0f} MB")
    if opts.evo is not None:
        compare_with_evo(opts.evo, cli, *write_pair(opts.workdir, *CASES["small"][:2]), opts.repeat)
    if opts.breakdown:
        print(f"phases of one evaluation of {CASES['small'][0]:,} / {CASES['small'][1]:,} poses:")
        breakdown(*write_pair(opts.workdir, *CASES["small"][:2]), opts.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
