"""The CI examples of docs/ci.md and the README run as the CI systems run them.

The YAML blocks are read with a YAML parser and their shell commands run in a temporary
folder laid out as the docs say (``data/groundtruth.tum``, ``runs/slam.tum``,
``ci/baseline/`` made by the docs' own baseline command), against generated runs: a run as
good as the baseline's (the gate passes, exit 0) and a regression (it fails the tolerance
and is worse than the baseline: exit 3). GitHub Actions' steps run with its default shell
(``bash -e -o pipefail``), a step after a failure only with ``if: always()``, and
``$GITHUB_STEP_SUMMARY`` is a file read back as Markdown; GitLab's ``script`` lines run in
order until one fails, then ``after_script``. The install step and the actions (``uses:``)
are left out: the test runs the loceval under test.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from junitparser import JUnitXml

from tests.exporters.ci.test_summary_md import headings, tables
from tests.verdict_factory import write_trial_runs

ROOT = Path(__file__).resolve().parents[1]
DOCS = (ROOT / "docs" / "ci.md").read_text(encoding="utf-8")
README = (ROOT / "README.md").read_text(encoding="utf-8")
INSTALL = "Install loceval"
"""The step (GitHub) that installs loceval; the test runs the checkout's instead."""


def _blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.DOTALL | re.MULTILINE)


def _yaml_blocks(text: str) -> list[Any]:
    return [yaml.safe_load(block) for block in _blocks(text, "yaml")]


def github_workflow() -> dict[str, Any]:
    """The docs' GitHub Actions workflow (the YAML block with ``jobs``)."""
    (workflow,) = [b for b in _yaml_blocks(DOCS) if isinstance(b, dict) and "jobs" in b]
    return workflow


def gitlab_job() -> dict[str, Any]:
    """The docs' GitLab CI job (the YAML block whose one job has a ``script``)."""
    found = [
        job
        for block in _yaml_blocks(DOCS)
        if isinstance(block, dict) and "jobs" not in block
        for job in block.values()
        if isinstance(job, dict) and "script" in job
    ]
    (job,) = found
    return job


@dataclass
class Ran:
    """What a CI job did: each step's name and exit code (None: skipped)."""

    steps: list[tuple[str, int | None]]

    def code(self, name: str) -> int | None:
        """The exit code of the step called ``name``."""
        return dict(self.steps)[name]


def _env(folder: Path, **extra: str) -> dict[str, str]:
    """The environment of a CI step: this loceval first on PATH, nothing of pytest's."""
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("CI", "GITHUB_", "PYTEST"))}
    return {**env, "PATH": path, "HOME": str(folder), **extra}


def _shell(command: str, folder: Path, env: dict[str, str]) -> int:
    # GitHub's default shell for run: bash --noprofile --norc -eo pipefail {0}
    done = subprocess.run(
        ["bash", "--noprofile", "--norc", "-eo", "pipefail", "-c", command],
        cwd=folder,
        env=env,
        check=False,
        timeout=900,
    )
    return done.returncode


def run_github(folder: Path, summary: Path) -> Ran:
    """Run the docs' workflow's steps as GitHub Actions runs them, in ``folder``."""
    (job,) = github_workflow()["jobs"].values()
    env = _env(folder, GITHUB_STEP_SUMMARY=str(summary), GITHUB_ACTIONS="true", CI="true")
    ran: list[tuple[str, int | None]] = []
    failed = False
    for step in job["steps"]:
        name = step.get("name") or step.get("uses", "")
        if "uses" in step or name == INSTALL:
            continue
        if failed and "always()" not in str(step.get("if", "")):
            ran.append((name, None))
            continue
        code = _shell(step["run"], folder, env)
        failed = failed or code != 0
        ran.append((name, code))
    return Ran(ran)


def run_gitlab(folder: Path) -> Ran:
    """Run the docs' GitLab job's script until a line fails, then its after_script."""
    job = gitlab_job()
    env = _env(folder, CI="true", GITLAB_CI="true", CI_PROJECT_DIR=str(folder))
    ran: list[tuple[str, int | None]] = []
    failed = False
    for k, line in enumerate(job["script"]):
        code = None if failed else _shell(line, folder, env)
        failed = failed or bool(code)
        ran.append((f"script {k}", code))
    for k, line in enumerate(job.get("after_script", ())):
        ran.append((f"after_script {k}", _shell(line, folder, env)))
    return Ran(ran)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The reference and three runs: the release's, a better one, one that regressed."""
    folder = tmp_path_factory.mktemp("runs")
    return write_trial_runs(folder, {"release": 0.01, "better": 0.008, "regressed": 0.2})


@pytest.fixture
def workspace(runs: dict[str, Path], tmp_path: Path) -> Path:
    """A checkout as the docs lay it out, its baseline made by the docs' baseline command."""
    (tmp_path / "data").mkdir()
    (tmp_path / "runs").mkdir()
    shutil.copy(runs["reference"], tmp_path / "data" / "groundtruth.tum")
    shutil.copy(runs["release"], tmp_path / "runs" / "slam.tum")
    (command,) = [b for b in _blocks(DOCS, "sh") if "--out ci/baseline" in b]
    assert _shell(command, tmp_path, _env(tmp_path)) == 0
    assert (tmp_path / "ci" / "baseline" / "result.json").is_file()
    assert (tmp_path / "ci" / "baseline" / "errors.csv").is_file()
    return tmp_path


def _build(workspace: Path, runs: dict[str, Path], run: str) -> None:
    """The build's replay step: this build's run where the docs expect it."""
    shutil.copy(runs[run], workspace / "runs" / "slam.tum")


def test_github_a_regression_closes_the_gate(workspace: Path, runs: dict[str, Path]) -> None:
    """The regressed run: the evaluate step exits 3, the job summary says why in a table."""
    _build(workspace, runs, "regressed")
    summary = workspace / "step_summary.md"
    ran = run_github(workspace, summary)
    assert ran.steps == [("Evaluate against the last release", 3), ("Job summary", 0)]
    text = summary.read_text(encoding="utf-8")
    assert headings(text)[0] == "groundtruth vs SLAM"
    results, against = tables(text)
    assert results[1][:2] == ["SLAM", "❌ FAIL"]
    assert [(row[0], row[1], row[6]) for row in against[1:]] == [
        ("SLAM", "ATE RMSE", "❌ worse"),
        ("SLAM", "RPE RMSE", "❌ worse"),
    ]
    assert all(row[5].endswith("(paired)") for row in against[1:])  # errors.csv kept
    assert "SLAM fails the tolerance (" in text
    assert "SLAM is worse than the baseline (ATE RMSE " in text
    junit = JUnitXml.fromfile(str(workspace / "loceval-out" / "junit.xml"))
    assert [(s.name, s.tests, s.failures) for s in junit] == [("SLAM", 3, 3)]


def test_github_a_better_run_passes(workspace: Path, runs: dict[str, Path]) -> None:
    """A run better than the release's: exit 0, and the summary says the gate passed."""
    _build(workspace, runs, "better")
    summary = workspace / "step_summary.md"
    ran = run_github(workspace, summary)
    assert ran.steps == [("Evaluate against the last release", 0), ("Job summary", 0)]
    text = summary.read_text(encoding="utf-8")
    assert "Gate: ✅ passed" in text
    results, against = tables(text)
    assert results[1][:2] == ["SLAM", "✅ PASS"]
    assert {row[6] for row in against[1:]} <= {"➖ within noise", "✅ better"}


def test_gitlab_a_regression_fails_the_job_and_keeps_the_report(
    workspace: Path, runs: dict[str, Path]
) -> None:
    """The job's script exits 3; after_script runs (no comment outside a merge request)."""
    _build(workspace, runs, "regressed")
    job = gitlab_job()
    ran = run_gitlab(workspace)
    assert ran.steps == [("script 0", 3), ("after_script 0", 0)]
    assert job["artifacts"]["when"] == "always"
    junit = JUnitXml.fromfile(str(workspace / job["artifacts"]["reports"]["junit"]))
    assert junit.failures == 3
    assert "allow_failure" not in job  # a closed gate fails the pipeline, as documented


def test_the_readme_steps_are_the_docs_steps() -> None:
    """The README's snippet is the docs' workflow's, step for step (so neither drifts)."""
    (snippet,) = [b for b in _yaml_blocks(README) if isinstance(b, dict) and "steps" in b]
    (job,) = github_workflow()["jobs"].values()
    documented = [{k: v for k, v in s.items() if k != "with"} for s in job["steps"]]
    for step in snippet["steps"]:
        assert {k: v for k, v in step.items() if k != "with"} in documented
    assert "docs/ci.md" in README


def test_both_jobs_run_the_same_evaluation() -> None:
    """GitHub's evaluate step and GitLab's script are the same command."""
    (job,) = github_workflow()["jobs"].values()
    (evaluate,) = [s["run"] for s in job["steps"] if str(s.get("run", "")).startswith("loceval")]
    assert gitlab_job()["script"] == [evaluate]
