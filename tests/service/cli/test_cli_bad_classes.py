"""Classes of bad input the core and readers must refuse clearly (issue 16), on the command line.

Each class failed at least once against a hostile corpus: server paths in messages about
zipped bags, files with a header and no rows, coordinates that overflow to infinity, EuRoC
files without their orientation, RPE deltas that make the pair search endless, and names
with terminal escapes. The contract is that of ``test_cli_bad_input``: exit 1, one
``loceval: error:`` line that names the problem and what to do, no traceback.
"""

from __future__ import annotations

import io
import re
import subprocess
import warnings
import zipfile
from pathlib import Path

import ezdxf
import numpy as np
import pytest

from tests import bagfactory as bf
from tests.cli_contract import cli_error_line, run_cli
from tests.factories import make_trajectory, perturb, write_motive, write_tum

HOSTILE_NAME = "evil\x1b[31m\u202e<script>alert(1)</script>"
"""A name with a terminal escape, a right-to-left override and HTML (NUL cannot be an argv)."""


def _cli(*argv: str | Path, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    """Run ``python -m service.cli ARGV`` from the project root (up to 180 s unless told)."""
    return run_cli(*argv, timeout=timeout)


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A TUM reference (200 poses, 100 Hz) and a noisy estimate of it."""
    folder = tmp_path_factory.mktemp("pair")
    rng = np.random.default_rng(16)
    truth = make_trajectory(rng, 200)
    reference = write_tum(folder / "reference.txt", truth)
    return reference, write_tum(folder / "estimate.txt", perturb(truth, rng))


# --- 1. zipped bags: members named inside the zip, never the extraction folder ------------


def _sqlite_bag(folder: Path) -> tuple[str, bytes, str]:
    """Return (metadata.yaml text, .db3 bytes, .db3 name) of a small ROS 2 sqlite3 bag."""
    rng = np.random.default_rng(3)
    poses = bf.random_poses(rng, 40, dt_ns=20_000_000)
    bag = bf.write_bag(
        bf.bag_path(folder, "sqlite3", "rec"), bf.pose_records("/pose", bf.POSE, poses),
        fmt="sqlite3",
    )  # fmt: skip
    db3 = next(bag.glob("*.db3"))
    return (bag / "metadata.yaml").read_text(), db3.read_bytes(), db3.name


def _zip(members: list[tuple[str, str | bytes]]) -> bytes:
    """Zip members in order; a name given twice is written twice (zipfile only warns)."""
    buffer = io.BytesIO()
    with (
        zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive,
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore", UserWarning)  # "Duplicate name": wanted here
        for name, content in members:
            archive.writestr(name, content)
    return buffer.getvalue()


def hostile_zips(folder: Path, marker: Path) -> dict[str, tuple[bytes, str]]:
    """The zipped bags of the hostile corpus: name -> (zip bytes, expected detail regex)."""
    meta, db3, db3_name = _sqlite_bag(folder)
    tag = f"!!python/object/apply:os.system ['touch {marker}']\n"
    db3_member = f"bag/{db3_name}"
    return {
        "only metadata.yaml": (
            _zip([("bag/metadata.yaml", meta)]),
            rf"rec\.zip:bag/{db3_name}",
        ),
        "duplicate member": (
            _zip([("bag/metadata.yaml", meta), ("bag/metadata.yaml", meta), (db3_member, db3)]),
            r"holds the member 'bag/metadata\.yaml' twice",
        ),
        "metadata names ../x.db3": (
            _zip([("bag/metadata.yaml", meta.replace(db3_name, "../x.db3")), (db3_member, db3)]),
            r"rec\.zip:bag/x\.db3",
        ),
        "python tag in metadata": (
            _zip([("bag/metadata.yaml", tag), (f"bag/{db3_name}", db3)]),
            r"rec\.zip:bag/metadata\.yaml",
        ),
        "truncated db3": (
            _zip([("bag/metadata.yaml", meta), (f"bag/{db3_name}", db3[:3000])]),
            rf"rec\.zip:bag/{db3_name}",
        ),
    }  # fmt: skip


ZIP_CASES = (
    "only metadata.yaml",
    "duplicate member",
    "metadata names ../x.db3",
    "python tag in metadata",
    "truncated db3",
)


@pytest.mark.parametrize("case", ZIP_CASES)
def test_zipped_bag_errors_name_members_not_server_folders(
    tmp_path: Path, pair: tuple[Path, Path], case: str
) -> None:
    """Inspect and evaluate of a broken zipped bag: ZIP:MEMBER in the message, no /tmp/ path."""
    marker = tmp_path / "pwned"
    content, detail = hostile_zips(tmp_path / "make", marker)[case]
    archive = tmp_path / "rec.zip"
    archive.write_bytes(content)
    for argv in (("inspect", archive), ("evaluate", f"{archive}@/pose", pair[1])):
        line = cli_error_line(_cli(*argv))
        assert "/tmp/" not in line, line  # noqa: S108  (no temporary folder is shown)
        assert "loceval-zip" not in line, line
        assert str(tmp_path) not in line, line
        assert re.search(detail, line), line
    assert not marker.exists()  # the YAML tag was never constructed


# --- 2. empty, whitespace-only and header-only files, for every text reader -----------------

EUROC_HEADER = (
    "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
)
EMPTY_FILES = [
    ("tum", "", r"holds no poses"),
    ("tum", "  \n\t\n", r"holds no poses"),
    ("tum", "# timestamp tx ty tz qx qy qz qw\n", r"holds no poses .*only a header or comments"),
    ("euroc", f"{EUROC_HEADER}\n", r"holds its header .* but no data rows"),
    ("euroc", "", r"holds no data rows"),
    ("euroc", " \n \n", r"holds no data rows"),
    ("kitti", "", r"holds no poses"),
    ("kitti", "\n\n# poses\n", r"holds no poses"),
    ("csv", "t,x,y,z,qx,qy,qz,qw\n", r"no rows of numbers under a header"),
    ("csv", "", r"no rows of numbers"),
    ("points", "id,x,y,z\n", r"has a header but no rows"),
    ("points", "\n \n", r"is empty"),
]


@pytest.mark.parametrize(("fmt", "content", "detail"), EMPTY_FILES)
def test_empty_and_header_only_files(
    tmp_path: Path, pair: tuple[Path, Path], fmt: str, content: str, detail: str
) -> None:
    """A file without data rows is refused with a sentence, for every reader (was exit 2)."""
    path = tmp_path / "run.csv"
    path.write_text(content)
    line = cli_error_line(_cli("evaluate", f"{fmt}:{path}", pair[1], "--formats", "result.json"))
    assert re.search(detail, line), line


@pytest.mark.parametrize("content", ["", "\n \t\n"])
def test_empty_file_without_prefix_is_called_empty(tmp_path: Path, content: str) -> None:
    """The sniffer calls an empty file empty instead of asking for a format prefix."""
    path = tmp_path / "run.txt"
    path.write_text(content)
    line = cli_error_line(_cli("inspect", path))
    assert "is empty" in line, line


def test_euroc_header_only_upload_without_prefix(tmp_path: Path) -> None:
    """The hostile corpus' case: a EuRoC CSV with its header and no rows, sniffed (was exit 2)."""
    path = tmp_path / "data.csv"
    path.write_text(EUROC_HEADER + "\n")
    line = cli_error_line(_cli("inspect", path))
    assert "no data rows" in line, line


def test_motive_header_only(tmp_path: Path) -> None:
    """A Motive take with its header rows and no frames has no poses."""
    truth = make_trajectory(np.random.default_rng(5), 20)
    take = write_motive(tmp_path / "take.csv", {"Body": truth})
    lines = take.read_bytes().split(b"\r\n")
    take.write_bytes(b"\r\n".join(lines[:7]) + b"\r\n")
    line = cli_error_line(_cli("inspect", f"motive:{take}@Body"))
    assert "holds no poses" in line, line


@pytest.mark.parametrize(
    ("which", "content", "detail"),
    [
        ("anchors", "id,x,y,z\n", r"0 anchors, but positioning needs at least 3"),
        ("anchors", " \n", r"the anchors file is empty"),
        ("ranges", "t,anchor_id,range_m\n", r"a header but no range rows"),
        ("ranges", "", r"the ranges file is empty"),
    ],
)
def test_radio_files_without_rows(
    tmp_path: Path, pair: tuple[Path, Path], which: str, content: str, detail: str
) -> None:
    """Anchors and ranges files without rows are refused with a sentence."""
    files = {
        "anchors": "id,x,y,z\nA,0,0,2\nB,9,0,2\nC,0,9,2\nD,9,9,2\n",
        "ranges": "t,anchor_id,range_m\n1.0,A,3.0\n",
        which: content,
    }
    for name, text in files.items():
        (tmp_path / f"{name}.csv").write_text(text)
    proc = _cli(
        "ranging", pair[0], "--anchors", tmp_path / "anchors.csv",
        "--ranges", tmp_path / "ranges.csv", "--formats", "result.json",
    )  # fmt: skip
    line = cli_error_line(proc)
    assert re.search(detail, line), line


# --- 3. coordinates that would overflow: bounded where they enter ---------------------------


@pytest.mark.parametrize(
    ("site", "detail"),
    [
        ("1e308 0 0 0", r"--site: The site transform has tx = 1e\+308 m, beyond ±1e\+09 m"),
        ("0 -5e9 0", r"--site: The site transform has ty = -5e\+09 m"),
        ("0 0 0 1e300", r"--site: The site transform's yaw must be within ±360 degrees"),
    ],
)
def test_site_beyond_any_coordinate(
    tmp_path: Path, pair: tuple[Path, Path], site: str, detail: str
) -> None:
    """A site of 1e308 m no longer reaches the JSON writer as inf (was exit 2)."""
    proc = _cli("evaluate", *pair, "--site", site, "--out", tmp_path / "out")
    line = cli_error_line(proc)
    assert re.search(detail, line), line
    assert not (tmp_path / "out").exists()


def test_site_matrix_beyond_any_coordinate(tmp_path: Path, pair: tuple[Path, Path]) -> None:
    """A site matrix whose translation is 1e308 m, or which scales 1e8-fold, is refused."""
    for matrix, detail in (
        ("1 0 0 1e308\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "has tx = 1e+308 m"),
        ("1e8 0 0 0\n0 1e8 0 0\n0 0 1e8 0\n0 0 0 1\n", "scales by 1e+08, outside 1e-06 to 1e+06"),
    ):
        path = tmp_path / "site.txt"
        path.write_text(matrix)
        out = tmp_path / "out"
        line = cli_error_line(_cli("evaluate", *pair, "--site-matrix", path, "--out", out))
        assert line.startswith("loceval: error: --site-matrix:"), line
        assert detail in line, line


def test_device_offset_beyond_a_lever_arm(pair: tuple[Path, Path]) -> None:
    """A device offset of 1e308 m is refused where it is parsed, naming the option."""
    line = cli_error_line(
        _cli("evaluate", *pair, "--offset", "1e308 0 0", "--formats", "result.json")
    )
    assert "--offset: The device offset's x y z [1e+308, 0.0, 0.0] exceed ±1000 m" in line, line


# --- 4. EuRoC without orientation columns ---------------------------------------------------


def test_euroc_without_orientation_is_refused_with_the_fix(
    tmp_path: Path, pair: tuple[Path, Path]
) -> None:
    """EuRoC's header without its q_RS_* columns is refused, naming them and the csv: prefix."""
    rows = np.loadtxt(pair[0])
    path = tmp_path / "gt.csv"
    body = "\n".join(
        f"{round(r[0] * 1e9)},{r[1]:.6f},{r[2]:.6f},{r[3]:.6f}" for r in rows
    )  # fmt: skip
    path.write_text("#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m]\n" + body + "\n")
    line = cli_error_line(_cli("evaluate", path, pair[1], "--formats", "result.json"))
    assert "no orientation columns (q_RS_w, q_RS_x, q_RS_y, q_RS_z)" in line, line
    assert f"csv:{path}" in line, line
    # The explicit choice reads it as position-only.
    ok = _cli("evaluate", f"csv:{path}", pair[1], "--formats", "result.json", "--json")
    assert ok.returncode == 0, ok.stderr
    assert "Rotation errors not computed: the reference has no orientations" in ok.stdout


# --- 5. RPE deltas bounded by what they can mean --------------------------------------------


@pytest.mark.parametrize(
    ("delta", "unit", "detail"),
    [
        ("1e-12", "s", r"median sampling interval \(0\.01 s\).* Use --rpe-delta 0\.01\.$"),
        ("1e-300", "m", r"below the reference's median step length .* Use --rpe-delta \d"),
    ],
)  # fmt: skip
@pytest.mark.parametrize("all_pairs", [False, True])
def test_rpe_delta_below_one_step(
    pair: tuple[Path, Path], delta: str, unit: str, detail: str, *, all_pairs: bool
) -> None:
    """A delta of 1e-12 s or 1e-300 m is refused at once (it made the pair search endless)."""
    extra = ["--rpe-all-pairs"] if all_pairs else []
    argv = ["evaluate", *pair, "--rpe-delta", delta, "--rpe-unit", unit, *extra]
    line = cli_error_line(_cli(*argv, "--formats", "result.json", timeout=60))
    assert line.startswith("loceval: error: --rpe-delta:"), line
    assert re.search(detail, line), line
    suggested = line.rsplit("Use --rpe-delta ", 1)[1].rstrip(".")
    ok = _cli("evaluate", *pair, "--rpe-delta", suggested, "--rpe-unit", unit, "--json", timeout=60)
    assert ok.returncode == 0, ok.stderr


# --- 6. names shown as text: no escapes, overrides or markup reach a terminal or a file ----


def test_hostile_names_are_shown_as_text(tmp_path: Path, pair: tuple[Path, Path]) -> None:
    """ESC, a bidi override and <script> in names: none raw in the terminal, HTML or DXF."""
    out = tmp_path / "out"
    proc = _cli(
        "evaluate", *pair, "--name", HOSTILE_NAME, "--reference-name", "ref\x1b[0m\x07",
        "--formats", "report.html,paths.dxf,result.json", "--out", out, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    for text in (proc.stdout, proc.stderr):
        assert "\x1b" not in text
        assert "\u202e" not in text
        assert "\x07" not in text
    assert "evil\ufffd[31m\ufffd<script>" in proc.stdout  # visible, not interpreted
    html = (out / "report.html").read_text(encoding="utf-8")
    for raw in ("\x1b", "\u202e", "\x07", "<script>alert"):
        assert raw not in html, raw
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    doc = ezdxf.readfile(out / "paths.dxf")
    names = [layer.dxf.name for layer in doc.layers]
    assert any(name.startswith("evil") for name in names), names
    for name in names:
        assert ezdxf.lldxf.validator.is_valid_layer_name(name), name
        assert not any(ch in name for ch in "\x1b\u202e\ufffd<>"), name


def test_error_messages_show_no_escapes(tmp_path: Path) -> None:
    """File names with a terminal escape or an override never reach the terminal raw."""
    for name in ("bad\x1b[2Jname.txt", "bad\u202eeman.txt"):
        path = tmp_path / name
        path.write_text("")
        proc = _cli("inspect", path)
        line = cli_error_line(proc)
        assert "\x1b" not in proc.stderr
        assert "\u202e" not in proc.stderr
        assert "is empty" in line, line
        assert repr(name)[1:-1] in line, line  # quoted names show escapes as escapes
