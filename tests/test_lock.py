"""The lock files pin every dependency of pyproject.toml, within its range, with hashes."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
LOCKS = ROOT / "requirements"
_PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;\\]+)")
# The environment the locks are resolved for (the Makefile's LOCK_PYTHON on Linux).
_ENV = {"python_version": "3.11", "sys_platform": "linux", "platform_system": "Linux"}


def _pins(name: str) -> dict[str, str]:
    """Return {canonical name: version} of a lock file; every pin carries a hash."""
    text = (LOCKS / name).read_text(encoding="utf-8")
    pins: dict[str, str] = {}
    for block in re.split(r"\n(?=\S)", text):
        match = _PIN.match(block)
        if match is None:
            continue
        assert "--hash=sha256:" in block, f"{name}: {match.group(1)} has no hash"
        pins[canonicalize_name(match.group(1))] = match.group(2)
    return pins


def _requirements(*extras: str) -> list[Requirement]:
    """Return the requirements of the project and of the extras, self-references expanded."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    optional = project["optional-dependencies"]
    seen: set[str] = set()
    todo, out = list(extras), [Requirement(r) for r in project["dependencies"]]
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for text in optional[extra]:
            req = Requirement(text)
            if canonicalize_name(req.name) == "loceval":
                todo.extend(req.extras)
            else:
                out.append(req)
    return out


@pytest.mark.parametrize(("lock", "extra"), [("runtime.lock", "all"), ("dev.lock", "dev")])
def test_lock_pins_every_dependency_within_its_range(lock: str, extra: str) -> None:
    """Each requirement of the extra is pinned in the lock at a version its range admits."""
    pins = _pins(lock)
    for req in _requirements(extra):
        if req.marker is not None and not Marker(str(req.marker)).evaluate(_ENV):
            continue
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} is not in requirements/{lock}; run `make lock`"
        assert req.specifier.contains(pins[name], prereleases=True), (
            f"requirements/{lock} pins {req.name}=={pins[name]} outside {req.specifier}; "
            "run `make lock`"
        )


def test_dev_lock_agrees_with_runtime_lock() -> None:
    """The dev set is the runtime set plus the tools, at the same versions."""
    runtime, dev = _pins("runtime.lock"), _pins("dev.lock")
    assert {n: dev.get(n) for n in runtime} == runtime


def test_build_lock_pins_the_build_backend() -> None:
    """The editable install's build backend comes from the lock too."""
    build = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["build-system"]
    pins = _pins("build.lock")
    for text in build["requires"]:
        req = Requirement(text)
        assert req.specifier.contains(pins[canonicalize_name(req.name)])


def test_makefile_installs_from_the_locks_with_hashes() -> None:
    """make setup and make test install the locked sets, hash-checked, and nothing unpinned."""
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert "--require-hashes" in makefile
    for lock in ("runtime.lock", "dev.lock", "build.lock"):
        assert f"requirements/{lock}" in makefile
    installs = [line for line in makefile.splitlines() if "pip install" in line]
    unpinned = [
        line for line in installs if "--require-hashes" not in line and "--no-deps" not in line
    ]
    assert unpinned == [line for line in unpinned if ".lockenv" in line]
