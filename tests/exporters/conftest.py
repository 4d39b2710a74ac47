"""Fixtures for exporter tests: a synthetic evaluation with two estimates."""

from __future__ import annotations

import ast
import json
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from exporters.options import ExportOptions
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.trajectory import Trajectory
from tests.conftest import require_tool

VALIDATOR_DIR = Path(__file__).resolve().parent / "gltf_validator"
GRASSHOPPER_SCRIPT = (
    Path(__file__).resolve().parents[2] / "exporters" / "grasshopper" / "loceval_paths.py"
)
Validator = Callable[[bytes], dict]


def walk(rng: np.random.Generator, *, n: int = 6000, rate_hz: float = 100.0) -> Trajectory:
    """A 60 s walk through two rooms: a rounded rectangle with a detour, z at 1.2-1.4 m."""
    t = np.arange(n) / rate_hz
    s = t / t[-1] * 2 * np.pi
    x = 4.0 * np.cos(s) + 1.5 * np.cos(3 * s)
    y = 3.0 * np.sin(s)
    z = 1.3 + 0.1 * np.sin(5 * s)
    positions = np.stack([x, y, z], axis=1)
    yaw = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    quat = Rotation.from_euler("zyx", np.stack([yaw, 0.02 * np.sin(s), 0 * s], 1)).as_quat()
    stamps = (1_700_000_000 * 10**9 + np.rint(t * 1e9)).astype(np.int64)
    del rng
    return Trajectory(stamps, positions, quat, name="OptiTrack", source="gt.tum", frame_id="map")


def noisy(
    rng: np.random.Generator,
    truth: Trajectory,
    *,
    every: int,
    sigma: float,
    drift: float,
    name: str,
) -> Trajectory:
    """An estimate at every n-th pose with noise, slow drift and a rigid frame change."""
    sel = truth.select(np.arange(0, len(truth), every))
    k = np.arange(len(sel))
    pos = sel.positions_xyz + rng.normal(0, sigma, (len(sel), 3)) + drift * k[:, None] / len(sel)
    frame = Rotation.from_euler("z", 30, degrees=True)
    quat = (frame * Rotation.from_quat(sel.quat_xyzw)).as_quat()
    return Trajectory(
        sel.stamps_ns,
        frame.apply(pos) + np.array([2.0, -1.0, 0.0]),
        quat,
        name=name,
        source=f"{name}.tum",
    )


@pytest.fixture
def two_estimates(rng: np.random.Generator) -> EvaluationResult:
    """Return an evaluation of RTAB-Map-like and Isaac-like estimates against a walk."""
    truth = walk(rng)
    a = noisy(rng, truth, every=3, sigma=0.02, drift=0.25, name="RTAB-Map")
    b = noisy(rng, truth, every=4, sigma=0.05, drift=0.05, name="ISAAC")
    return evaluate(truth, [a, b], EvaluationConfig(tolerance=Tolerance(0.10, 0.95)))


def with_reference_loss(result: EvaluationResult) -> EvaluationResult:
    """Evaluate ``result``'s estimates again after a 3 s tracking loss of the reference.

    The reference loses its poses after 20 s up to and including 23 s (``times_s()``).
    """
    ref = result.reference
    times = ref.times_s()
    return evaluate(
        ref.select(np.flatnonzero((times < 20.0) | (times > 23.0))),
        [e.estimate for e in result.estimates],
        result.config,
    )


def expected_paths(result: EvaluationResult, options: ExportOptions) -> list[np.ndarray]:
    """Reference then aligned estimates after the site transform and unit scale."""
    trajectories = [result.reference, *(e.aligned for e in result.estimates)]
    return [
        options.site.apply_positions(t.positions_xyz) * options.units.per_metre
        for t in trajectories
    ]


def curve_vertices(curve: Any) -> np.ndarray:
    """Return a rhino3dm PolylineCurve's vertices as an (N, 3) array."""
    points = [curve.Point(k) for k in range(curve.PointCount)]
    return np.array([[p.X, p.Y, p.Z] for p in points])


def grasshopper_script_keys() -> set[str]:
    """Return the string keys the Grasshopper script subscripts (``x["key"]``)."""
    tree = ast.parse(GRASSHOPPER_SCRIPT.read_text(encoding="utf-8"))
    return {
        node.slice.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Subscript)
        and isinstance(node.slice, ast.Constant)
        and isinstance(node.slice.value, str)
    }


@pytest.fixture(scope="session")
def validate(tmp_path_factory: pytest.TempPathFactory) -> Validator:
    """Return a function running the pinned Khronos glTF Validator on GLB bytes."""
    node = require_tool("node")
    npm = require_tool("npm")
    if not (VALIDATOR_DIR / "node_modules" / "gltf-validator").is_dir():
        install = subprocess.run(
            [npm, "ci", "--prefix", str(VALIDATOR_DIR), "--no-audit", "--no-fund"],
            capture_output=True,
            text=True,
            check=False,
            timeout=600,
        )
        assert install.returncode == 0, install.stdout + install.stderr
    folder = tmp_path_factory.mktemp("gltf-validator")

    def run(data: bytes) -> dict:
        path = folder / "model.glb"
        path.write_bytes(data)
        done = subprocess.run(
            [node, str(VALIDATOR_DIR / "validate.js"), str(path)],
            capture_output=True,
            text=True,
            check=False,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr
        report: dict = json.loads(done.stdout)
        return report

    return run
