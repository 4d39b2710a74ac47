"""The source syntax ``[FORMAT:]PATH[@SELECTOR]`` (loceval.readers.source)."""

from __future__ import annotations

from pathlib import Path

import pytest

from loceval.errors import ReaderError
from loceval.readers import SourceSpec, TrajectoryFormat, parse_source

F = TrajectoryFormat


class TestParseSource:
    def test_plain_path(self):
        """A bare path has no format, selector or options."""
        assert parse_source("run/gt.txt") == SourceSpec(None, Path("run/gt.txt"))

    @pytest.mark.parametrize("fmt", list(TrajectoryFormat))
    def test_format_prefix(self, fmt):
        """Every format name works as a prefix, in any case."""
        spec = parse_source(f"{fmt.value.upper()}:a/b.x")
        assert spec.format is fmt
        assert spec.path == Path("a/b.x")

    def test_prefix_must_be_a_format(self):
        """Windows drives and other colons stay part of the path."""
        assert parse_source(r"C:\data\gt.txt").path == Path(r"C:\data\gt.txt")
        assert parse_source("run:2.txt").format is None

    def test_default_format(self):
        """The default format applies without a prefix and yields to one."""
        assert parse_source("a.txt", default_format=F.KITTI).format is F.KITTI
        assert parse_source("tum:a.txt", default_format=F.KITTI).format is F.TUM

    def test_bag_selectors(self):
        """Topics and tf chains are selectors."""
        assert parse_source("run.mcap@/amcl_pose").selector == "/amcl_pose"
        spec = parse_source("bag:run.bag@tf:map:base_link")
        assert (spec.format, spec.path, spec.selector) == (
            F.BAG,
            Path("run.bag"),
            "tf:map:base_link",
        )

    def test_motive_body_and_option(self):
        """A rigid body name (with spaces) plus an option."""
        spec = parse_source("motive:take.csv@Rigid Body 1, up=z")
        assert spec.selector == "Rigid Body 1"
        assert dict(spec.options) == {"up": "z"}

    def test_options_only(self):
        """``KEY=VALUE`` items are options, keys lower-cased, values kept."""
        spec = parse_source("csv:log.csv@T=Time_s,x=PX")
        assert spec.selector is None
        assert dict(spec.options) == {"t": "Time_s", "x": "PX"}

    def test_kitti_times(self):
        """The KITTI times file is an option."""
        spec = parse_source("kitti:00.txt@times=times.txt")
        assert spec.options["times"] == "times.txt"

    def test_existing_path_with_at_and_colon_wins(self, tmp_path, monkeypatch):
        """A file whose name contains '@' or a format-like prefix is read as that file."""
        monkeypatch.chdir(tmp_path)
        (tmp_path / "tum:a@b.txt").write_text("x")
        assert parse_source("tum:a@b.txt") == SourceSpec(None, Path("tum:a@b.txt"))
        (tmp_path / "data@2024").mkdir()
        (tmp_path / "data@2024" / "run.bag").write_text("x")
        spec = parse_source("data@2024/run.bag@/odom")
        assert (spec.path, spec.selector) == (Path("data@2024/run.bag"), "/odom")

    def test_two_selectors(self):
        """Two plain items after '@' are refused."""
        with pytest.raises(ReaderError, match=r"names two selectors, 'a' and 'b'"):
            parse_source("x.bag@a,b")

    def test_empty(self):
        """An empty source is refused with an example."""
        with pytest.raises(ReaderError, match=r"Empty source; give a file"):
            parse_source("  ")

    @pytest.mark.parametrize("text", ["tum:", "@/odom", "bag:@/odom"])
    def test_no_path(self, text):
        """A prefix or selector without a path is refused."""
        with pytest.raises(ReaderError, match=r"names no file; give one"):
            parse_source(text)

    def test_unlookupable_names_are_paths(self):
        """Names the OS refuses to look up (NUL, too long) still parse."""
        assert parse_source("a\x00b.txt").path == Path("a\x00b.txt")
        long_name = "x" * 5000
        assert parse_source(f"{long_name}@/odom").selector == "/odom"

    def test_str_round_trips(self):
        """``str(spec)`` parses back to the same spec."""
        spec = SourceSpec(F.MOTIVE, Path("t.csv"), "Drone", {"up": "z"})
        assert str(spec) == "motive:t.csv@Drone,up=z"
        assert parse_source(str(spec)) == spec

    def test_options_are_read_only(self):
        """Options cannot be changed after parsing."""
        spec = parse_source("csv:a.csv@t=x")
        with pytest.raises(TypeError):
            spec.options["t"] = "y"  # type: ignore[index]
