"""``loceval evaluate --system NAME ... --baseline PATH``: trials and a baseline from the CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from tests.factories import make_trajectory, perturb, write_tum
from tests.loceval.results.test_baseline import _evo_zip


def _trials(tmp_path: Path, rng, levels: dict[str, float], tag: str) -> tuple[list[str], list[str]]:
    """Write 4 trials per system; return their files and the --system/--name arguments."""
    truth = make_trajectory(np.random.default_rng(3), n=800)
    write_tum(tmp_path / "gt.txt", truth)
    files, flags = [], []
    for system, sigma in levels.items():
        for k in range(4):
            trial = replace(perturb(truth, rng, sigma_m=sigma * (1 + 0.05 * k)), name="x")
            files.append(str(write_tum(tmp_path / f"{tag}-{system}-{k}.txt", trial)))
            flags += ["--system", system]
    return files, flags


def test_trials_and_a_baseline_folder(tmp_path: Path, rng, capsys):
    """The first run's --out folder is the baseline of the second: per system, worse / within
    noise / better; the tables print the systems and the baseline."""
    files, flags = _trials(tmp_path, rng, {"orb": 0.02, "vins": 0.03, "rtab": 0.05}, "v1")
    out = tmp_path / "v1"
    code = main(["evaluate", str(tmp_path / "gt.txt"), *files, *flags, "--no-ci", "--out", str(out),
                 "--formats", "result.json,errors.csv"])  # fmt: skip
    assert code == 0
    capsys.readouterr()
    files, flags = _trials(tmp_path, rng, {"orb": 0.04, "vins": 0.03, "rtab": 0.025}, "v2")
    assert main(["evaluate", str(tmp_path / "gt.txt"), *files, *flags, "--no-ci",
                 "--baseline", str(out), "--json"]) == 0  # fmt: skip
    document = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in document["systems"]] == ["orb", "vins", "rtab"]
    assert document["systems"][0]["metrics"]["ate_rmse"]["n"] == 4
    verdicts = {
        c["name"]: c["verdict"]
        for c in document["baseline"]["comparisons"]
        if c["metric"] == "ate_rmse"
    }
    assert verdicts == {"orb": "worse", "vins": "within_noise", "rtab": "better"}
    assert main(["evaluate", str(tmp_path / "gt.txt"), *files, *flags, "--no-ci",
                 "--baseline", str(out / "result.json")]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert "Systems over their trials" in printed
    assert "Against the baseline v1 (a loceval result)" in printed
    assert "orb (system), ATE RMSE" in printed


def test_an_evo_zip_as_baseline(tmp_path: Path, rng, capsys):
    """An evo APE zip of the same estimate file pairs by its stamps: within the noise."""
    truth = make_trajectory(np.random.default_rng(3), n=800)
    write_tum(tmp_path / "gt.txt", truth)
    estimate = write_tum(tmp_path / "orb.txt", perturb(truth, rng, sigma_m=0.02))
    assert main(["evaluate", str(tmp_path / "gt.txt"), str(estimate), "--no-ci", "--json"]) == 0
    ate = json.loads(capsys.readouterr().out)["estimates"][0]["ate"]["translation_m"]
    rmse = ate["rmse"]
    errors = np.full(800, rmse)  # the same RMSE at every stamp
    zipped = _evo_zip(
        tmp_path / "orb_ape.zip",
        title="APE w.r.t. translation part (m)\n(with SE(3) Umeyama alignment)",
        est_name="orb.txt",
        stamps_s=truth.stamps_ns / 1e9,
        errors=errors,
    )
    assert main(["evaluate", str(tmp_path / "gt.txt"), str(estimate), "--no-ci", "--json",
                 "--baseline", str(zipped)]) == 0  # fmt: skip
    (found,) = json.loads(capsys.readouterr().out)["baseline"]["comparisons"]
    assert found["name"] == "orb"
    assert found["paired"]
    assert found["baseline"] == pytest.approx(rmse)
    assert found["difference"] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--system", "orb"], "Give --system once per estimate"),
        (["--baseline", "no/such/folder"], "--baseline: No baseline 'no/such/folder'"),
    ],
)
def test_bad_trial_arguments(tmp_path: Path, rng, capsys, extra, message):
    """A --system count that differs from the estimates, or a missing baseline: one line, exit 1."""
    files, _ = _trials(tmp_path, rng, {"orb": 0.02}, "v1")
    assert main(["evaluate", str(tmp_path / "gt.txt"), *files[:2], *extra]) == 1
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err
