"""Shared fixtures: the seeded RNG, the public recordings, and system tools."""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("dev", deadline=None, max_examples=30)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

PUBLIC_DATA = Path(
    os.environ.get(
        "LOCEVAL_PUBLIC_DATA",
        Path(__file__).resolve().parents[1].parent / "shared" / "data" / "public",
    )
)


def in_ci() -> bool:
    """Whether the CI variable is set: missing data or tools then fail instead of skipping."""
    return bool(os.environ.get("CI"))


def skip_or_fail(reason: str) -> None:
    """Skip with ``reason`` on a user's machine; fail in CI, where everything must be there."""
    if in_ci():
        pytest.fail(f"{reason} (CI is set, so this is a failure, not a skip)")
    pytest.skip(reason)


@pytest.fixture
def no_weasyprint(monkeypatch: pytest.MonkeyPatch) -> None:
    """WeasyPrint cannot be loaded, as where its system libraries (pango) are missing.

    The cached outcome of :func:`exporters.report.render._weasyprint` is cleared, so the
    next PDF (or :func:`exporters.report.pdf_available`) looks again and finds none.
    """
    from exporters.report import render as report_render

    monkeypatch.setattr(report_render, "_weasyprint_loaded", None)
    monkeypatch.setitem(sys.modules, "weasyprint", None)  # `import weasyprint` raises


@pytest.fixture
def html_only_templates(tmp_path: Path) -> Path:
    """A copy of the repository's templates without its Typst ones: a user's HTML templates.

    Its PDFs are laid out from the HTML by WeasyPrint (the optional loceval[html-pdf]).
    """
    source = Path(__file__).resolve().parents[1] / "templates"
    folder = tmp_path / "html-templates"
    shutil.copytree(source, folder, ignore=shutil.ignore_patterns("*.typ", "_typst"))
    return folder


@pytest.fixture
def rng() -> np.random.Generator:
    """Return the one seeded random generator tests use."""
    return np.random.default_rng(20240601)


@pytest.fixture(scope="session")
def public_data() -> Path:
    """Return the folder of public recordings, or skip (fail in CI) when it is absent."""
    if not (PUBLIC_DATA / "README.md").is_file():
        skip_or_fail(
            f"public recordings not found at {PUBLIC_DATA}; set LOCEVAL_PUBLIC_DATA to "
            "the shared/data/public folder"
        )
    return PUBLIC_DATA


def require_tool(name: str) -> str:
    """Return the path of a system tool, or skip (fail in CI) when it is not installed."""
    path = shutil.which(name)
    if path is None:
        skip_or_fail(f"{name!r} is not installed (see .ci/run for the package that has it)")
    assert path is not None
    return path


@functools.cache
def pdf_unavailable() -> str | None:
    """Why WeasyPrint cannot lay out PDFs here, or None when it can.

    WeasyPrint lays out only the PDFs of HTML templates of one's own (the optional
    loceval[html-pdf], with the system libraries pango); the repository's reports are
    typeset by Typst and need neither.

    Probed in a subprocess, so a missing library's import-time warning or error stays there.
    """
    probe = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", "import weasyprint"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode == 0:
        return None
    last = (probe.stderr.strip().splitlines() or ["import failed"])[-1]
    return (
        f"WeasyPrint (for PDFs of HTML templates of one's own) cannot be loaded ({last[:200]}); "
        "install loceval[html-pdf] and the packages that .ci/run installs (libpango-1.0-0 "
        "libpangoft2-1.0-0)"
    )


def pytest_runtest_setup(item: pytest.Item) -> None:
    """Tests marked ``pdf`` need WeasyPrint and pango: skip without them (fail in CI)."""
    if item.get_closest_marker("pdf") is not None:
        reason = pdf_unavailable()
        if reason is not None:
            skip_or_fail(reason)
