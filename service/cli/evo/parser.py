"""The parsers of ``loceval ape``, ``loceval rpe`` and ``loceval res``: evo's command lines.

``loceval ape FORMAT REF EST [flags]`` as ``evo_ape`` takes it: the format word and its
arguments (``tum``/``kitti``/``euroc`` REF EST, ``bag``/``bag2`` BAG REF_TOPIC EST_TOPIC),
then evo's flags with evo's defaults (nearest stamp within 10 ms, no alignment,
``trans_part``). A flag evo has and loceval does not, or a mistyped one, is refused naming it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

from service.cli.usage import EXIT_INPUT, fail, unknown_arguments

__all__ = ["EVO_COMMANDS", "FORMATS", "RELATIONS", "UNSUPPORTED", "add_evo_commands"]

FORMATS: Final = ("tum", "kitti", "euroc", "bag", "bag2", "mcap")
"""evo's format words; the bags take a file and two topics."""

RELATIONS: Final = ("full", "trans_part", "rot_part", "angle_deg", "angle_rad", "point_distance")

DELTA_UNITS: Final = ("f", "d", "r", "m")
"""frames, degrees, radians, metres (evo's ``--delta_unit``)."""

UNSUPPORTED: Final[dict[str, str]] = {
    "--plot_mode": "the report draws plan and side views",
    "--plot_colormap_max": "the report colours the path by the error itself",
    "--plot_colormap_min": "the report colours the path by the error itself",
    "--plot_colormap_max_percentile": "the report colours the path by the error itself",
    "--plot_full_ref": "the report draws the whole reference",
    "--plot_x_dimension": "the report plots against seconds",
    "--ros_map_yaml": "a floor plan goes in with loceval evaluate --building FILE.dxf",
    "--serialize_plot": "the report is HTML (and PDF)",
    "--logfile": "redirect the output instead",
    "--no_warnings": "loceval prints its notes after the figures",
    "--debug": "bugs print a traceback anyway",
    "-c": "write the flags on the command line",
    "--config": "write the flags on the command line",
    "--project_to_plane": "loceval evaluate --planar measures in x-y",
    "--downsample": "not available",
    "--motion_filter": "not available",
    "--change_unit": "not available",
    "--merge": "not available",
}
"""evo flags loceval does not take, and what to do instead."""


class _EvoParser(argparse.ArgumentParser):
    """argparse for evo's command lines: exit 1, and name an unknown or unsupported flag."""

    def error(self, message: str) -> Any:  # noqa: ANN401  (NoReturn on argparse's side)
        self.print_usage(sys.stderr)
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message}\n")

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """Parse; an argument nobody took is one error line naming it (and why, for evo's own)."""
        parsed, extras = super().parse_known_args(args, namespace)
        if extras and getattr(self, "strict", False):
            fail(self, unknown_arguments(self, extras, hint=_unsupported))
        return parsed, extras


def _unsupported(flag: str) -> str | None:
    """Return why loceval does not take evo's ``flag``, or None for a flag evo lacks too."""
    if flag not in UNSUPPORTED:
        return None
    return f"evo's {flag} is not supported by loceval: {UNSUPPORTED[flag]}"


def _common(parser: argparse.ArgumentParser, *, rpe: bool) -> None:
    """Add the flags shared by every format of ``ape`` and ``rpe``."""
    align = parser.add_argument_group("alignment")
    align.add_argument("-a", "--align", action="store_true", help="SE(3) Umeyama alignment")
    align.add_argument(
        "-s", "--correct_scale", action="store_true", help="correct the scale (Sim(3) with -a)"
    )
    align.add_argument(
        "--n_to_align", type=int, default=-1, metavar="N",
        help="the number of poses to use for the alignment (default: all)",
    )  # fmt: skip
    align.add_argument(
        "--align_origin", action="store_true", help="align the origins of the trajectories"
    )
    metric = parser.add_argument_group("metric")
    metric.add_argument(
        "-r", "--pose_relation", default="trans_part", choices=RELATIONS,
        help="the pose relation the error measures (default: trans_part)",
    )  # fmt: skip
    if rpe:
        metric.add_argument("-d", "--delta", type=float, default=1.0, help="the RPE delta")
        metric.add_argument(
            "-u", "--delta_unit", default="f", choices=DELTA_UNITS,
            help="the delta's unit: f frames, d degrees, r radians, m metres (default: f)",
        )  # fmt: skip
        metric.add_argument(
            "-t", "--delta_tol", type=float, default=0.1, metavar="TOL",
            help="relative delta tolerance for --all_pairs (default: 0.1)",
        )  # fmt: skip
        metric.add_argument("--all_pairs", action="store_true", help="every pose starts a pair")
        metric.add_argument(
            "--pairs_from_reference", action="store_true",
            help="measure the delta along the reference (default: along the estimate)",
        )  # fmt: skip
    sync = parser.add_argument_group("time")
    sync.add_argument(
        "--t_max_diff", type=float, default=0.01, metavar="S",
        help="the largest stamp difference of a match, seconds (default: 0.01)",
    )  # fmt: skip
    sync.add_argument(
        "--t_offset", type=float, default=0.0, metavar="S",
        help="added to the estimate's stamps, seconds (default: 0)",
    )  # fmt: skip
    sync.add_argument(
        "--sync_method", default="nearest_time", choices=("nearest_time", "interpolation"),
        help="nearest_time only (loceval evaluate interpolates)",
    )  # fmt: skip
    sync.add_argument("--t_start", type=float, default=None, metavar="S", help="first stamp used")
    sync.add_argument("--t_end", type=float, default=None, metavar="S", help="last stamp used")
    out = parser.add_argument_group("output")
    out.add_argument(
        "-p", "--plot", action="store_true",
        help="write loceval's report (report.html) and print its path",
    )  # fmt: skip
    out.add_argument(
        "--save_plot", type=Path, default=None, metavar="PATH",
        help="write the plots as evo does: PATH.pdf one PDF of both, PATH.png (.svg ...) "
        "PATH_raw.png and PATH_map.png, no suffix PNG",
    )  # fmt: skip
    out.add_argument(
        "--save_results", type=Path, default=None, metavar="FILE.zip",
        help="write the result zip (evo_res reads it)",
    )  # fmt: skip
    out.add_argument("-v", "--verbose", action="store_true", help="print what was done")
    out.add_argument("--silent", action="store_true", help="print nothing")


def _add_metric(sub: Any, name: str, *, rpe: bool) -> None:  # noqa: ANN401
    what = "relative" if rpe else "absolute"
    cmd = sub.add_parser(
        name,
        help=f"evo_{name}'s command line: the {what} pose error",
        description=(
            f"evo_{name}'s command line on loceval's pipeline: FORMAT REF EST with evo's flags "
            "and defaults (nearest stamp within --t_max_diff, no alignment without -a, "
            "trans_part), followed by loceval's 95 %% intervals and notes."
        ),
    )
    formats = cmd.add_subparsers(
        dest="evo_format", required=True, metavar="FORMAT", parser_class=_EvoParser
    )
    for fmt in FORMATS:
        bag = fmt in {"bag", "bag2", "mcap"}
        sub_cmd = formats.add_parser(
            fmt,
            help="a ROS bag and two topics" if bag else f"two {fmt} files",
            description=f"loceval {name} {fmt}: evo_{name}'s flags.",
        )
        sub_cmd.strict = True
        if bag:
            sub_cmd.add_argument("bag", help="the bag (ROS 1 .bag; ROS 2 folder, .db3, .mcap)")
            sub_cmd.add_argument("ref_topic", help="the reference's topic (or tf:PARENT:CHILD)")
            sub_cmd.add_argument("est_topic", help="the estimate's topic")
        else:
            sub_cmd.add_argument("ref_file", help="the reference")
            sub_cmd.add_argument("est_file", help="the estimate")
        _common(sub_cmd, rpe=rpe)
        sub_cmd.set_defaults(handler=f"service.cli.evo.metric:run_{name}", metric=name)


EVO_COMMANDS: Final = ("ape", "rpe", "res")
"""The evo-style commands :func:`add_evo_commands` adds, in its order."""


def add_evo_commands(sub: Any) -> None:  # noqa: ANN401  (argparse's private subparsers action)
    """Add ``ape``, ``rpe`` and ``res`` to the ``loceval`` parser."""
    _add_metric(sub, "ape", rpe=False)
    _add_metric(sub, "rpe", rpe=True)
    res = sub.add_parser(
        "res",
        help="evo_res: compare result zips of evo and loceval",
        description=(
            "Read result zips (evo_ape/evo_rpe --save_results, loceval ape/rpe "
            "--save_results), print evo_res's table and write a comparison report with "
            "paired intervals where the zips hold the error series."
        ),
    )
    res.add_argument("result_files", nargs="+", type=Path, metavar="ZIP")
    res.add_argument("--out", type=Path, default=None, metavar="DIR", help="write the report here")
    res.add_argument(
        "--use_filenames", action="store_true", help="name the results by their file names"
    )
    res.set_defaults(handler="service.cli.evo.compare:run_res")
