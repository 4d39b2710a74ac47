"""``auto`` time and device offsets on the CLI and the API: options, JSON, report section."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.errors import InputError
from service.cli import main
from service.jobs.evaluations import check_options
from service.schemas.evaluations import EvaluationOptions
from tests import bagfactory as bf
from tests.calibration_factory import TRUE_DEVICE, Recording, make_recording
from tests.factories import write_tum
from tests.service._api_fixtures import assert_problem, open_api

CHEAP = {"formats": ["result.json"]}


@pytest.fixture(scope="module")
def recording() -> Recording:
    """A 60 s handheld recording: 45 ms delay, a camera 11 cm from the rigid body."""
    return make_recording(np.random.default_rng(20240601), duration_s=60.0)


@pytest.fixture(scope="module")
def files(recording: Recording, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The recording as TUM files (reference, estimate)."""
    folder = tmp_path_factory.mktemp("offsets")
    return (
        write_tum(folder / "truth.txt", recording.reference),
        write_tum(folder / "camera.txt", recording.estimate),
    )


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, object]:
    assert main(list(argv)) == 0
    doc: dict[str, object] = json.loads(capsys.readouterr().out)
    estimates = doc["estimates"]
    assert isinstance(estimates, list)
    first: dict[str, object] = estimates[0]
    return first


def test_cli_auto_offsets_and_report(
    files: tuple[Path, Path],
    recording: Recording,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """--time-offset auto --device auto: both applied, in the JSON and the report's section."""
    ref, est = files
    out = tmp_path / "out"
    doc = _json(
        capsys, "evaluate", str(ref), str(est), "--time-offset", "auto", "--device", "auto",
        "--json", "--out", str(out), "--formats", "report.html",
    )  # fmt: skip
    clock, device = doc["time_offset"], doc["device_offset"]
    assert isinstance(clock, dict)
    assert isinstance(device, dict)
    assert clock["source"] == "estimated"
    assert doc["time_offset_s"] == pytest.approx(recording.time_offset_s, abs=0.001)
    assert device["source"] == "estimated"
    np.testing.assert_allclose(device["translation_m"], recording.device.translation, atol=0.002)
    assert all(s is not None and s < 0.002 for s in device["sigma_translation_m"])
    html = (out / "report.html").read_text()
    section = re.search(r'<section id="clocks".*?</section>', html, re.DOTALL)
    assert section is not None
    assert "<h2>Clocks and device offset</h2>" in section.group(0)
    assert 'data-plot="clock_correlation"' in section.group(0)
    assert 'src="data:image/svg+xml;base64,' in section.group(0)
    assert "Time offset estimated (1 sigma)" in section.group(0)


def test_cli_default_clock_is_checked(
    files: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --time-offset, 0 is applied and the 45 ms the data show is a warning."""
    ref, est = files
    doc = _json(capsys, "evaluate", str(ref), str(est), "--json")
    assert doc["time_offset_s"] == 0.0
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert clock["source"] == "given"
    assert clock["estimated_s"] == pytest.approx(-0.045, abs=0.001)
    assert doc["device_offset"] is None
    notes = doc["warnings"]
    assert isinstance(notes, list)
    assert any(
        re.search(r"lags the ground truth by 4\d\.\d+ ± 0\.\d+ ms .*you gave 0\.0 ms", w)
        for w in notes
    )


def test_cli_bad_values_exit_1(
    files: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """--time-offset soon is a usage error; --device auto with --offset is refused."""
    ref, est = files
    with pytest.raises(SystemExit) as stop:
        main(["evaluate", str(ref), str(est), "--time-offset", "soon"])
    assert stop.value.code == 1
    assert "--time-offset: takes a number or auto, got 'soon'" in capsys.readouterr().err
    code = main(["evaluate", str(ref), str(est), "--device", "auto", "--offset", "0 0 0.1"])
    assert code == 1
    assert "either with --offset or as --device auto, not both" in capsys.readouterr().err


def test_api_auto_offsets(files: tuple[Path, Path], recording: Recording, tmp_path: Path) -> None:
    """Over HTTP ``time_offset_s: "auto"`` and ``device: "auto"`` reach the result."""
    ref, est = files
    with open_api(tmp_path) as api:
        ref_id = api.dataset("truth.txt", ref.read_bytes())["id"]
        est_id = api.dataset("camera.txt", est.read_bytes())["id"]
        body = {
            "reference": {"dataset_id": ref_id},
            "estimates": [{"dataset_id": est_id}],
            "options": {**CHEAP, "time_offset_s": "auto", "device": "auto"},
        }
        evaluation = api.evaluate(body).json()
        assert evaluation["status"] == "succeeded", evaluation
        url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/result.json"
        result = api.client.get(url, headers=api.headers).json()
        estimate = result["estimates"][0]
        assert estimate["time_offset"]["source"] == "estimated"
        assert estimate["time_offset_s"] == pytest.approx(recording.time_offset_s, abs=0.001)
        assert estimate["device_offset"]["source"] == "estimated"
        assert result["options"]["auto_device"] is True


@pytest.mark.parametrize(
    ("options", "detail"),
    [
        ({"time_offset_s": "soon"}, r"options\.time_offset_s: .*or 'auto', got 'soon'"),
        ({"device": "soon"}, r"options\.device: .*or 'auto', got 'soon'"),
        ({"time_offset_s": 2e9}, r"options\.time_offset_s: .*less than or equal to 1000000000"),
    ],
)
def test_api_bad_values_are_422(tmp_path: Path, options: dict[str, object], detail: str) -> None:
    """A time offset or device that is neither a value nor ``auto`` is refused with 422."""
    with open_api(tmp_path) as api:
        body = {
            "reference": {"dataset_id": "R"},
            "estimates": [{"dataset_id": "E"}],
            "options": {**CHEAP, **options},
        }
        assert_problem(api.evaluate(body), 422, detail=detail)


def test_api_device_auto_and_offset_is_refused() -> None:
    """``device: "auto"`` beside an ``offset`` fails before anything is queued."""
    options = EvaluationOptions(device="auto", offset="0 0 0.1")
    with pytest.raises(InputError, match=r"either as offset or as device, not both"):
        check_options(options)
    assert EvaluationOptions.model_validate(options.model_dump(mode="json")) == options


PUBLIC = {
    # key: (reference, estimate, extra flags, measured offset s, measured sigma s). Measured
    # with this code through the CLI (loceval evaluate REF EST --time-offset auto --json),
    # 2026-11-23; evo's users take 0 for all three (TUM and EuRoC are synchronised).
    "fr2_desk": (
        "fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", ["--align", "sim3"], -0.009365, 0.000242,
    ),
    "fr1_xyz": (
        "freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt", [], -0.015711, 0.001982,
    ),
    "v102": ("euroc:V102_groundtruth.csv", "V102.txt", [], 0.000966, 0.000827),
}  # fmt: skip


@pytest.mark.public_data
@pytest.mark.parametrize("key", sorted(PUBLIC))
def test_public_recordings_auto_clock(
    key: str, public_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """On TUM's and EuRoC's recordings the CLI finds a few ms, with a sigma of at most 2 ms."""
    ref_name, est_name, flags, offset_s, sigma_s = PUBLIC[key]
    prefix, sep, rest = ref_name.partition(":")
    ref = f"{prefix}:{public_data / rest}" if sep else str(public_data / ref_name)
    doc = _json(
        capsys, "evaluate", ref, str(public_data / est_name), *flags, "--time-offset", "auto",
        "--json",
    )  # fmt: skip
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert clock["source"] == "estimated"
    assert clock["value_s"] == pytest.approx(offset_s, abs=2e-6)
    assert clock["sigma_s"] == pytest.approx(sigma_s, abs=2e-6)
    assert doc["time_offset_s"] == pytest.approx(offset_s, abs=2e-6)


def test_cli_bag_device_link_is_compared(
    recording: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bag's /tf_static device link is applied as given and agrees with the motion."""
    ref, est = recording.reference, recording.estimate
    assert ref.quat_xyzw is not None
    assert est.quat_xyzw is not None
    link = TRUE_DEVICE.inverse()  # the robot's tree mounts the rig on base_link
    static = bf.Tf(
        int(est.stamps_ns[0]),
        "base_link",
        "rig",
        link.translation,
        Rotation.from_matrix(np.array(link.rotation)).as_quat(),
    )
    records = [
        *bf.pose_records(
            "/mocap/rig",
            bf.POSE,
            bf.Poses(ref.stamps_ns, ref.positions_xyz, ref.quat_xyzw),
            frame_id="mocap",
            child_frame_id="rig",
        ),
        *bf.tf_records(
            bf.link_transforms(
                "odom", "base_link", bf.Poses(est.stamps_ns, est.positions_xyz, est.quat_xyzw)
            )
        ),
        *bf.tf_records([static], topic="/tf_static"),
    ]
    bag = bf.write_bag(bf.bag_path(tmp_path, "sqlite3"), records, fmt="sqlite3")
    doc = _json(
        capsys, "evaluate", f"{bag}@/mocap/rig", f"{bag}@tf:odom:base_link",
        "--device", str(bag), "--device-from", "rig", "--device-to", "base_link",
        "--time-offset", "auto", "--json",
    )  # fmt: skip
    device = doc["device_offset"]
    assert isinstance(device, dict)
    assert device["source"] == "urdf"
    np.testing.assert_allclose(device["translation_m"], TRUE_DEVICE.translation, atol=1e-9)
    notes = doc["warnings"]
    assert isinstance(notes, list)
    message = next(w for w in notes if "differs from the URDF" in w)
    assert "within 3 sigma, so the two agree" in message
