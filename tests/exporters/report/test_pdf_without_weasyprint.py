"""report.pdf is made in a fresh environment that holds loceval[report] and nothing more.

The proof has to be honest about what is installed: a venv made with
``--system-site-packages`` sees the dev environment's WeasyPrint, and hiding the module in
the test's own process (``sys.modules["weasyprint"] = None``) still runs with every other
package of the dev tools at hand. So the test makes a new venv (no system site packages) and
installs into it exactly the distributions that ``pyproject.toml``'s core dependencies and
``report`` extra need, closed over their own requirements, at the versions and hashes of
``requirements/runtime.lock`` (``pip install --no-deps --require-hashes``: pip's cache makes
it a matter of seconds, and nothing unpinned can slip in). WeasyPrint is then not installed
at all, nor cffi, pango's bindings or the service's packages, and the repository's code,
on that venv's path, typesets a report, the summary and the control-point report.
"""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from tests.conftest import require_tool

ROOT = Path(__file__).resolve().parents[3]
_ENV = {"python_version": f"{sys.version_info.major}.{sys.version_info.minor}", "extra": ""}

SCRIPT = r"""
import sys
from pathlib import Path

import numpy as np

from exporters.options import ExportOptions
from exporters.report import render_report_pdf
from loceval.evaluation import EvaluationConfig, Tolerance, evaluate
from loceval.trajectory import Trajectory

try:
    import weasyprint  # noqa: F401
except ModuleNotFoundError:
    pass
else:
    sys.exit("weasyprint is importable in the report-only environment")

rng = np.random.default_rng(4)
n = 3000
t = np.arange(n, dtype=np.int64) * 10_000_000
angle = np.linspace(0.0, 4.0 * np.pi, n)
xyz = np.stack([3.0 * np.cos(angle), 2.0 * np.sin(angle), 0.1 * np.sin(3.0 * angle)], axis=1)
quat = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
truth = Trajectory(t, xyz, quat, name="ground truth")
noisy = xyz[::2] + rng.normal(0.0, 0.02, (n // 2, 3))
estimate = Trajectory(t[::2], noisy, quat[::2], name="VIO")
result = evaluate(truth, [estimate], EvaluationConfig(tolerance=Tolerance(0.05, 0.95)))
pdf = render_report_pdf(result, ExportOptions(title="No WeasyPrint here"))
Path(sys.argv[1]).write_bytes(pdf)
assert "weasyprint" not in sys.modules
print("typst", __import__("typst").__version__)
"""


def _report_closure() -> set[str]:
    """Canonical names of the core and ``report`` requirements, closed over their own."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    todo = [Requirement(r) for r in project["dependencies"]]
    todo += [Requirement(r) for r in project["optional-dependencies"]["report"]]
    seen: set[str] = set()
    while todo:
        req = todo.pop()
        if req.marker is not None and not Marker(str(req.marker)).evaluate(_ENV):
            continue
        name = canonicalize_name(req.name)
        if name in seen:
            continue
        seen.add(name)
        todo += [Requirement(r) for r in importlib.metadata.requires(req.name) or []]
    return seen


def _locked(names: set[str]) -> str:
    """The runtime lock's entries (pins and hashes) of ``names``; every name must be there."""
    text = (ROOT / "requirements" / "runtime.lock").read_text(encoding="utf-8")
    blocks = {}
    for block in re.split(r"\n(?=\S)", text):
        found = re.match(r"([A-Za-z0-9][A-Za-z0-9._-]*)==", block)
        if found:
            lines = [line for line in block.splitlines() if not line.strip().startswith("#")]
            kept = "\n".join(lines)
            blocks[canonicalize_name(found.group(1))] = kept.rstrip(" \\")
    assert names <= set(blocks), sorted(names - set(blocks))
    return "\n".join(blocks[name] for name in sorted(names)) + "\n"


def test_the_report_extra_holds_no_weasyprint() -> None:
    """Neither the report extra's closure nor the runtime lock names WeasyPrint or pango's."""
    closure = _report_closure()
    assert "typst" in closure
    assert not closure & {"weasyprint", "cffi", "pydyf", "tinycss2", "cssselect2"}
    lock = (ROOT / "requirements" / "runtime.lock").read_text(encoding="utf-8")
    assert not re.search(r"^weasyprint==", lock, flags=re.MULTILINE)


@pytest.mark.slow
def test_report_pdf_in_a_venv_without_weasyprint(tmp_path: Path) -> None:
    """A fresh venv with loceval[report]'s locked wheels only: report.pdf, text and fonts."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    requirements = tmp_path / "report.txt"
    requirements.write_text(_locked(_report_closure()), encoding="utf-8")
    subprocess.run(
        [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
         "--no-deps", "--require-hashes", "--only-binary=:all:", "-r", str(requirements)],
        check=True,
    )  # fmt: skip
    installed = subprocess.run(
        [str(python), "-m", "pip", "list", "--format=freeze", "--disable-pip-version-check"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    names = {canonicalize_name(line.split("==")[0]) for line in installed.split()}
    assert "weasyprint" not in names
    assert "typst" in names
    pdf = tmp_path / "report.pdf"
    run = subprocess.run(
        [str(python), "-c", SCRIPT, str(pdf)],
        capture_output=True,
        text=True,
        check=False,
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "MPLCONFIGDIR": str(tmp_path)},
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert pdf.read_bytes().startswith(b"%PDF")
    text = subprocess.run(
        [require_tool("pdftotext"), str(pdf), "-"], capture_output=True, text=True, check=True
    ).stdout
    assert "No WeasyPrint here" in text
    assert "VIO does not meet the tolerance" in text or "VIO meets the tolerance" in text
    fonts = subprocess.run(
        [require_tool("pdffonts"), str(pdf)], capture_output=True, text=True, check=True
    ).stdout.splitlines()[2:]
    assert fonts
    assert all(re.search(r"\byes\s+yes\s+yes\b", line) for line in fonts), fonts
    assert any("DejaVuSans" in line for line in fonts), fonts
