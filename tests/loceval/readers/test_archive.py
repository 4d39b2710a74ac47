"""Tests for loceval.readers._archive: safe extraction of zipped bags."""

from __future__ import annotations

import stat
import zipfile
from pathlib import Path

import pytest

from loceval.errors import ReaderError
from loceval.readers._archive import (
    extract_zip,
    extracted_bag,
    find_bag,
    zip_contains_bag,
)


def make_zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


@pytest.fixture
def bag_zip(tmp_path: Path) -> Path:
    return make_zip(
        tmp_path / "rec.zip",
        {"rec/metadata.yaml": b"rosbag2_bagfile_information: {}\n", "rec/rec_0.db3": b"x" * 100},
    )


def test_extracts_a_bag_directory(bag_zip, tmp_path):
    """A zipped ROS 2 bag directory extracts, and find_bag returns the folder."""
    target = tmp_path / "out"
    target.mkdir()
    files = extract_zip(bag_zip, target)
    assert sorted(f.name for f in files) == ["metadata.yaml", "rec_0.db3"]
    assert find_bag(target, what="rec.zip") == [(target / "rec").resolve()]


def test_temporary_directory_is_removed(bag_zip):
    """extracted_bag removes its temporary directory on exit, also after an error."""
    with extracted_bag(bag_zip) as paths:
        folder = paths[0]
        assert (folder / "metadata.yaml").is_file()
    assert not folder.exists()
    seen: list[Path] = []

    def fail_inside() -> None:
        with extracted_bag(bag_zip) as inner:
            seen.append(inner[0])
            raise RuntimeError

    with pytest.raises(RuntimeError):
        fail_inside()
    assert not seen[0].exists()


def test_caller_directory_is_kept(bag_zip, tmp_path):
    """A caller-given directory is used and left in place."""
    target = tmp_path / "keep"
    with extracted_bag(bag_zip, target_dir=target) as paths:
        assert paths[0].is_relative_to(target.resolve())
    assert (target / "rec" / "metadata.yaml").is_file()


@pytest.mark.parametrize(
    "name", ["../evil.txt", "rec/../../evil.txt", "/etc/evil.txt", "C:/evil.txt", "..\\evil.txt"]
)
def test_traversal_refused(tmp_path, name):
    """Members whose path leaves the target folder are refused before anything is written."""
    archive = make_zip(tmp_path / "bad.zip", {"rec/metadata.yaml": b"x", name: b"boom"})
    target = tmp_path / "out"
    target.mkdir()
    with pytest.raises(ReaderError, match="leaves the extraction folder"):
        extract_zip(archive, target)
    assert not list(target.iterdir())
    assert not (tmp_path / "evil.txt").exists()


def test_symlink_refused(tmp_path):
    """Symbolic link members are refused."""
    path = tmp_path / "link.zip"
    with zipfile.ZipFile(path, "w") as archive:
        info = zipfile.ZipInfo("rec/metadata.yaml")
        info.external_attr = (stat.S_IFLNK | 0o777) << 16
        archive.writestr(info, "/etc/passwd")
    with pytest.raises(ReaderError, match="symbolic link"):
        extract_zip(path, tmp_path)


def test_encrypted_refused(tmp_path):
    """Members flagged as encrypted are refused."""
    path = tmp_path / "enc.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("rec/metadata.yaml", b"x")
    data = bytearray(path.read_bytes())
    # Set bit 0 of the general purpose flags in the local and the central header.
    for signature, flag_offset in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        at = data.find(signature)
        data[at + flag_offset] |= 0x1
    path.write_bytes(bytes(data))
    with pytest.raises(ReaderError, match="encrypted"):
        extract_zip(path, tmp_path)


def test_zip_bomb_refused(tmp_path):
    """A member that inflates more than max_ratio is refused without extracting it."""
    archive = make_zip(tmp_path / "bomb.zip", {"rec/rec_0.db3": bytes(8 * 1024**2)})
    assert archive.stat().st_size < 64 * 1024
    target = tmp_path / "out"
    target.mkdir()
    with pytest.raises(ReaderError, match="zip bomb"):
        extract_zip(archive, target)
    assert not list(target.rglob("*.db3"))


def test_total_size_limit(bag_zip, tmp_path):
    """More content than max_total_bytes is refused."""
    with pytest.raises(ReaderError, match="more than the limit of 50"):
        extract_zip(bag_zip, tmp_path, max_total_bytes=50)


def test_no_bag_lists_contents(tmp_path):
    """A zip without a bag names what it holds."""
    archive = make_zip(tmp_path / "docs.zip", {"notes.txt": b"hi", "img/a.png": b"png"})
    with (
        pytest.raises(ReaderError, match=r"holds no bag.*img/a.png, notes.txt"),
        extracted_bag(archive),
    ):
        pass


def test_several_bags_refused(tmp_path):
    """A zip with two bag folders is refused, listing them."""
    archive = make_zip(tmp_path / "two.zip", {"a/metadata.yaml": b"x", "b/metadata.yaml": b"x"})
    with pytest.raises(ReaderError, match="several bags"), extracted_bag(archive):
        pass


@pytest.mark.parametrize(
    "members",
    [
        {"one/run.bag": b"b", "two/run.mcap": b"m"},
        {"dir/metadata.yaml": b"x", "dir/run_0.db3": b"d", "loose.mcap": b"m"},
        {"dir/metadata.yaml": b"x", "other.bag": b"b"},
    ],
)
def test_bags_of_different_kinds_refused(tmp_path, members):
    """A ROS 1 bag beside an MCAP, or a loose file beside a bag folder, is ambiguous."""
    archive = make_zip(tmp_path / "mixed.zip", members)
    with pytest.raises(ReaderError, match="several bags"), extracted_bag(archive):
        pass


def test_storage_files_inside_the_bag_folder_belong_to_it(tmp_path):
    """The .db3 files of a bag folder do not count as bags of their own."""
    archive = make_zip(tmp_path / "dir.zip", {"rec/metadata.yaml": b"x", "rec/rec_0.db3": b"d"})
    with extracted_bag(archive) as paths:
        assert [p.name for p in paths] == ["rec"]


def test_split_ros1_bags(tmp_path):
    """Several .bag files are one split ROS 1 recording, sorted by name."""
    archive = make_zip(tmp_path / "r1.zip", {"run_1.bag": b"b", "run_0.bag": b"a"})
    with extracted_bag(archive) as paths:
        assert [p.name for p in paths] == ["run_0.bag", "run_1.bag"]


def test_single_mcap(tmp_path):
    """A zipped .mcap file is found."""
    archive = make_zip(tmp_path / "m.zip", {"deep/dir/run.mcap": b"m"})
    with extracted_bag(archive) as paths:
        assert [p.name for p in paths] == ["run.mcap"]


def test_not_a_zip(tmp_path):
    """A file that is not a zip is a ReaderError."""
    path = tmp_path / "fake.zip"
    path.write_bytes(b"not a zip")
    with pytest.raises(ReaderError, match="not a readable zip"):
        extract_zip(path, tmp_path)


def test_missing_zip(tmp_path):
    """A missing zip is a ReaderError."""
    with pytest.raises(ReaderError, match="does not exist"):
        extract_zip(tmp_path / "nope.zip", tmp_path)


def test_zip_contains_bag(bag_zip, tmp_path):
    """zip_contains_bag looks at member names only."""
    assert zip_contains_bag(bag_zip)
    assert not zip_contains_bag(make_zip(tmp_path / "d.zip", {"a.txt": b"x"}))
    (tmp_path / "junk.zip").write_bytes(b"junk")
    assert not zip_contains_bag(tmp_path / "junk.zip")


def test_too_many_members_refused(tmp_path):
    """A zip of more members than any bag folder holds is refused before extracting."""
    archive = tmp_path / "many.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        for i in range(10_001):
            zf.writestr(f"f{i}", b"")
    with pytest.raises(ReaderError, match="10,001 members"), extracted_bag(archive):
        pass
