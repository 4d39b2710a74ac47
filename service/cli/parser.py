"""The argument parser of every command; ``loceval evaluate``'s options come from the table.

The flags of :data:`loceval.options.OPTIONS` are generated here: each option's flag,
default, choices and help, stored under its key (``--max-dt`` in ``args.max_dt_s``), so
:func:`service.jobs.options.config_from_options` reads the parsed arguments as the API's options.
Bounds are checked where both front doors meet them: in the core's ``EvaluationConfig``.
Handlers are named ``"module:function"`` and imported only when their command runs.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, Final, NoReturn

from loceval import __version__
from loceval.errors import InputError
from loceval.options import AUTO, OPTIONS, OptionKind, OptionSpec
from service.cli.evo.hints import EVALUATE_EPILOG, evo_hint
from service.cli.evo.parser import EVO_COMMANDS, add_evo_commands
from service.cli.usage import EXIT_INPUT, fail, unknown_arguments

__all__ = [
    "EXIT_BUG",
    "EXIT_GATE",
    "EXIT_INPUT",
    "add_evaluation_arguments",
    "build_parser",
    "check_names",
    "command_names",
    "names",
    "numbers",
    "systems_of",
]

EXIT_BUG = 2
EXIT_GATE = 3
"""The gate closed: ``--fail-on`` named a condition that holds (the last line says which)."""

_DESCRIPTION = "The loceval command line: {commands}."
"""The top-level description; its list of commands is read from the parser (issue 44)."""


class _Parser(argparse.ArgumentParser):
    """argparse that exits 1 on a usage error: a bad option is bad input, not a bug."""

    def error(self, message: str) -> NoReturn:
        missing = re.fullmatch(r"argument (--[\w-]+).*: expected one argument", message)
        if missing:
            # argparse takes "-1e6" or "-0.1,0.2" for an option unless glued to its flag.
            flag = missing.group(1)
            message += f"; for a value that starts with '-' write {flag}=VALUE"
        self.print_usage(sys.stderr)
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message}\n")

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """Parse; an argument nobody took is one error line naming the nearest valid flag.

        Each command answers for its own arguments (``loceval evaluate: error: unknown
        option --algin; did you mean --align?``), not argparse's top-level usage; a command
        with ``flag_hint`` says what it calls evo's flags.
        """
        parsed, extras = super().parse_known_args(args, namespace)
        if extras:
            fail(self, unknown_arguments(self, extras, hint=getattr(self, "flag_hint", None)))
        return parsed, extras


class _FormatNames:
    """The names of the trajectory formats, read from the readers when first needed.

    argparse checks a value with ``in`` and lists the names in ``--help``; neither happens
    for ``loceval --help``, which therefore does not import the readers (and numpy).
    """

    def __contains__(self, name: object) -> bool:
        return name in set(self)

    def __iter__(self) -> Iterator[str]:
        from loceval.readers.source import TrajectoryFormat  # noqa: PLC0415

        return iter([f.value for f in TrajectoryFormat])


def check_names(args: argparse.Namespace) -> None:
    """``--name`` is given once per estimate, or not at all (``loceval submit``'s rule too).

    Raises:
        InputError: as many names as estimates are not given.
    """
    if args.name and len(args.name) != len(args.estimates):
        msg = (
            f"Give --name once per estimate: {len(args.estimates)} estimates but "
            f"{len(args.name)} names."
        )
        raise InputError(msg)


def systems_of(args: argparse.Namespace) -> list[str | None]:
    """Return each estimate's system from ``--system`` (given once per estimate, or never).

    Raises:
        InputError: ``--system`` is given, but not once per estimate.
    """
    if not args.system:
        return [None] * len(args.estimates)
    if len(args.system) != len(args.estimates):
        msg = (
            f"Give --system once per estimate, in order like --name ('' for an estimate of "
            f"no system): {len(args.estimates)} estimates but {len(args.system)} systems."
        )
        raise InputError(msg)
    return [s.strip() or None for s in args.system]


def numbers(text: str) -> tuple[float, ...]:
    """Parse the CLI's ``0.05,0.1`` list of metres (the thresholds).

    Raises:
        InputError: an item is not a number (the error names the thresholds option).
    """
    try:
        return tuple(float(t) for t in text.split(",") if t.strip())
    except ValueError:
        msg = f"The thresholds take metres separated by commas like 0.05,0.1, got {text!r}."
        raise InputError(msg, option="thresholds_m") from None


def names(text: str) -> list[str] | None:
    """Parse the CLI's ``report.html,paths.dxf`` list of names; None when empty."""
    parsed = [n.strip() for n in text.split(",") if n.strip()]
    return parsed or None


class _Names(argparse.Action):
    """A list of names, comma-separated or the flag repeated (``--fail-on fail --fail-on worse``).

    The first use replaces the table's default; each further use adds its names.
    """

    def __call__(
        self,
        _parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        _option_string: str | None = None,
    ) -> None:
        current = getattr(namespace, self.dest, None)
        given = list(values or ())
        if isinstance(current, list):  # given before on this command line: add to it
            given = current + [n for n in given if n not in current]
        setattr(namespace, self.dest, given or None)


def _number_or_auto(text: str) -> float | str:
    """Parse a number of seconds, or ``auto`` (estimated from the data)."""
    if text.strip().lower() == AUTO:
        return AUTO
    try:
        return float(text)
    except ValueError:
        msg = f"takes a number or {AUTO}, got {text!r}"
        raise argparse.ArgumentTypeError(msg) from None


def _path_or_auto(text: str) -> Path | str:
    """Return a file's path, or ``auto`` (estimated from the data)."""
    return AUTO if text.strip().lower() == AUTO else Path(text)


def _folder(text: str) -> Path:
    """Return the --out folder; an empty name is a usage error."""
    if not text.strip():
        msg = "needs a folder name, e.g. --out results/run1"
        raise argparse.ArgumentTypeError(msg)
    return Path(text)


def _shown(spec: OptionSpec) -> str:
    """Return the option's help with its default, as the table gives them."""
    default = spec.default
    if default is None or spec.kind is OptionKind.SWITCH:
        return spec.help
    if isinstance(default, tuple):
        shown = ",".join(v if isinstance(v, str) else f"{v:g}" for v in default)
        return f"{spec.help} (default: {shown})"
    return f"{spec.help} (default: {default})"


def add_option(parser: argparse.ArgumentParser, spec: OptionSpec) -> None:
    """Add one option of the table as a flag stored under its key."""
    common: dict[str, Any] = {"dest": spec.key, "help": _shown(spec)}
    if spec.kind is OptionKind.SWITCH:
        parser.add_argument(spec.flag, action="store_true", **common)
        return
    common.update(default=spec.default, metavar=spec.metavar)
    kind = spec.kind
    if kind is OptionKind.CHOICE:
        common.update(choices=[str(c) for c in spec.choices], metavar=None)
    elif kind is OptionKind.NUMBER:
        common["type"] = _number_or_auto if spec.auto else float
    elif kind is OptionKind.INTEGER:
        common["type"] = int
    elif kind is OptionKind.NUMBERS:
        common["type"] = numbers
    elif kind is OptionKind.NAMES:
        common.update(type=names, action=_Names)
    elif kind in {OptionKind.FILE, OptionKind.MATRIX, OptionKind.DEVICE}:
        common["type"] = _path_or_auto if spec.auto else Path
    parser.add_argument(spec.flag, **common)
    if kind is OptionKind.DEVICE:
        parser.add_argument(
            "--device-from", default=None, metavar="LINK", help="the rigid body's link"
        )
        parser.add_argument("--device-to", default=None, metavar="LINK", help="the sensor's link")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Return the argument parser of every subcommand, or of ``command``'s alone.

    A command line that names its command needs only that command's flags: building every
    subcommand took about 8 ms of each run (argparse formats each flag's help as it adds
    it). Without a known command (``--help``, ``--version``, a mistyped name) every
    subcommand is built, so the help and the errors list them all.

    Args:
        command: the first word of the command line (None: build every subcommand).
    """
    parser = _Parser(prog="loceval")
    parser.add_argument("--version", action="version", version=f"loceval {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    wanted = [add for names, add in _COMMANDS if command in names]
    for add in wanted or [add for _, add in _COMMANDS]:
        add(sub)
    parser.description = _DESCRIPTION.format(commands=", ".join(command_names()))
    return parser


def command_names() -> list[str]:
    """Return every subcommand's name, in the order the help lists them."""
    return [name for names, _ in _COMMANDS for name in names]


def _add_inspect_and_demo(sub: Any) -> None:  # noqa: ANN401  (argparse's subparsers action)
    ins = sub.add_parser("inspect", help="list what a recording holds")
    ins.add_argument("path", help="a bag, bag directory, zip, MCAP or trajectory file")
    ins.add_argument("--json", action="store_true", help="print the inspection as JSON")
    ins.set_defaults(handler="service.cli.inspection:run_inspect")

    demo = sub.add_parser(
        "demo", help="write a synthetic recording and evaluate it (no data needed)"
    )
    demo.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR")
    demo.set_defaults(handler="service.cli.evaluate:run_demo")


def _add_evaluate(sub: Any) -> None:  # noqa: ANN401  (argparse's private subparsers action)
    ev = sub.add_parser(
        "evaluate",
        help="evaluate estimates against a reference",
        description=(
            "Evaluate one or more estimated trajectories against a reference. A source is "
            "[FORMAT:]PATH[@SELECTOR]: tum:gt.txt, kitti:poses.txt@times=times.txt, "
            "motive:take.csv@RigidBody, run.mcap@/amcl_pose, run.bag@tf:map:base_link."
        ),
    )
    add_evaluation_arguments(ev)
    ev.set_defaults(handler="service.cli.evaluate:run_evaluate")


def add_evaluation_arguments(ev: argparse.ArgumentParser) -> None:
    """Add the sources, names and options of ``loceval evaluate`` (``loceval submit``'s too)."""
    ev.epilog = EVALUATE_EPILOG
    ev.flag_hint = evo_hint  # type: ignore[attr-defined]  # read by _Parser with getattr
    ev.add_argument("reference", help="the ground truth source")
    ev.add_argument("estimates", nargs="+", metavar="estimate", help="estimate sources")
    ev.add_argument(
        "--name", action="append", default=[], help="estimate name, once per estimate in order"
    )
    ev.add_argument(
        "--system",
        action="append",
        default=[],
        metavar="NAME",
        help="the system an estimate is a trial (a run) of, once per estimate in order like "
        "--name ('' for an estimate of no system); trials of one system are grouped, "
        "summarised (median, mean, spread, interval over trials) and compared",
    )
    ev.add_argument("--reference-name", default=None, help="name of the reference")
    ev.add_argument(
        "--format",
        choices=_FormatNames(),
        default=None,
        metavar="FORMAT",
        help="format of sources without a FORMAT: prefix, one of %(choices)s (default: sniffed "
        "from content)",
    )
    for spec in OPTIONS:
        if spec.cli and spec.group != "ranging":
            add_option(ev, spec)
    _add_result_flags(ev)


def _add_result_flags(parser: argparse.ArgumentParser) -> None:
    """Add ``--json`` and ``--out`` of the commands that evaluate (evaluate, ranging)."""
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument(
        "--out", type=_folder, default=None, metavar="DIR", help="write artifacts here"
    )


RANGING_SKIPPED: Final = frozenset(
    {"offset", "device", "map", "map_estimate", "clutter_m", "baseline", "min_trial_coverage"}
)
"""Evaluation options ``loceval ranging`` does not take (the tag offset says where the tag is)."""


def _add_ranging(sub: Any) -> None:  # noqa: ANN401  (argparse's private subparsers action)
    rg = sub.add_parser(
        "ranging",
        help="evaluate radio ranges per anchor and the positions solved from them",
        description=(
            "Evaluate the range measurements of a radio system (UWB, BLE) per anchor against "
            "the true distances from the reference, position the tag from the ranges (NLLS, "
            "Min-Max) and evaluate those positions like any estimate (alignment none by "
            "default: the anchors are in building coordinates; x-y only in 2D)."
        ),
    )
    rg.add_argument("reference", help="the ground truth source ([FORMAT:]PATH[@SELECTOR])")
    rg.add_argument(
        "--anchors", required=True, type=Path, metavar="FILE", help="anchors CSV: id,x,y,z"
    )
    rg.add_argument(
        "--ranges",
        required=True,
        metavar="SOURCE",
        help="ranges CSV t,anchor_id,range_m[,rssi], or BAG@TOPIC of sensor_msgs/msg/Range",
    )
    rg.add_argument("--reference-name", default=None, help="name of the reference")
    rg.add_argument(
        "--format",
        choices=_FormatNames(),
        default=None,
        metavar="FORMAT",
        help="format of the reference without a FORMAT: prefix (default: sniffed)",
    )
    for spec in OPTIONS:
        if spec.key == "align":  # the anchors are in building coordinates already
            spec = replace(spec, default="none")  # noqa: PLW2901
        if spec.cli and spec.key not in RANGING_SKIPPED:
            add_option(rg, spec)
    _add_result_flags(rg)
    # The options it does not take keep their defaults, so the option builders see every key.
    skipped = {spec.key: spec.default for spec in OPTIONS if spec.key in RANGING_SKIPPED}
    rg.set_defaults(handler="service.cli.ranging:run_ranging", **skipped)


def _add_report(sub: Any) -> None:  # noqa: ANN401  (argparse's private subparsers action)
    report = sub.add_parser(
        "report",
        help="one summary report over many recordings (as a schedule run makes it)",
        description=(
            "Evaluate each recording with the same template and write one summary report "
            "(summary.html and summary.pdf, or the files --formats names): a row per "
            "recording, a trend per system, the systems side by side, and the repeatability "
            "of the reference paths."
        ),
    )
    report.add_argument(
        "--datasets",
        nargs="+",
        required=True,
        type=Path,
        metavar="FILE",
        help="recordings, and result zips of evo_ape/evo_rpe (their figures, marked evo)",
    )
    report.add_argument(
        "--template",
        required=True,
        type=Path,
        metavar="FILE",
        help='JSON: {"reference": {"selector": ...}, "estimates": [...], "options": {...}}',
    )
    report.add_argument("--out", required=True, type=_folder, metavar="DIR")
    report.add_argument("--title", default="Summary report", help="the report's title")
    report.add_argument(
        "--formats",
        type=names,
        default=None,
        metavar="NAME,...",
        help="summary files to write: summary.html, summary.pdf (default: both)",
    )
    report.set_defaults(handler="service.cli.report:run_report")


def _add_service(sub: Any) -> None:  # noqa: ANN401  (argparse's private subparsers action)
    serve = sub.add_parser(
        "serve",
        help="start the HTTP service with its queue consumer (settings: LOCEVAL_* variables)",
    )
    serve.add_argument(
        "--host", default=None, help="address to listen on (default: LOCEVAL_HOST or 127.0.0.1)"
    )
    serve.add_argument(
        "--port", type=int, default=None, help="port to listen on (default: LOCEVAL_PORT or 8000)"
    )
    serve.add_argument(
        "--no-consumer",
        action="store_true",
        help="do not run jobs in this process (run `loceval worker` processes instead)",
    )
    serve.set_defaults(handler="service.cli.serve:run_serve")

    worker = sub.add_parser("worker", help="run queue consumers only (scale-out)")
    worker.set_defaults(handler="service.cli.serve:run_worker")

    keys = sub.add_parser("keys", help="create or revoke API keys")
    keys_sub = keys.add_subparsers(dest="keys_command", required=True, parser_class=_Parser)
    create = keys_sub.add_parser("create", help="create a key and print it (shown only once)")
    create.add_argument("--project", required=True, help="the project (created if new)")
    create.set_defaults(handler="service.cli.serve:run_keys_create")
    revoke = keys_sub.add_parser("revoke", help="revoke a key")
    revoke.add_argument("key", help="the key, or its first 12 characters")
    revoke.set_defaults(handler="service.cli.serve:run_keys_revoke")

    storage = sub.add_parser("storage", help="move the service's files into object storage")
    storage_sub = storage.add_subparsers(
        dest="storage_command", required=True, parser_class=_Parser
    )
    migrate = storage_sub.add_parser(
        "migrate",
        help="copy a data folder's uploads and artifacts into LOCEVAL_BLOB_URL's bucket and "
        "point the database at them (stop the service first; running it again continues)",
    )
    migrate.add_argument(
        "--from",
        dest="source",
        default=None,
        help="the data folder to copy from (default: LOCEVAL_DATA_DIR)",
    )
    migrate.set_defaults(handler="service.cli.storage:run_storage_migrate")


def _add_server(parser: argparse.ArgumentParser) -> None:
    """Add ``--server`` of the commands that talk to a loceval service."""
    parser.add_argument(
        "--server",
        required=True,
        metavar="URL",
        help="the loceval service, e.g. http://evalbox:8000 (the key: LOCEVAL_API_KEY)",
    )
    parser.add_argument(
        "--chunk-mib",
        type=float,
        default=16.0,
        metavar="MIB",
        help="size of one upload part; a dropped connection sends at most this again (default: 16)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def _add_client(sub: Any) -> None:  # noqa: ANN401  (argparse's private subparsers action)
    upload = sub.add_parser(
        "upload",
        help="upload recordings to a loceval service, resumably (site laptops)",
        description=(
            "Upload files to a loceval service in parts (the tus protocol): a dropped "
            "connection continues from where it broke, and running the same command again "
            "continues an upload that stopped. Prints each dataset: id, name, kind. The key "
            "of your project comes from LOCEVAL_API_KEY."
        ),
    )
    upload.add_argument("files", nargs="+", metavar="FILE", help="the files to upload")
    upload.add_argument("--tags", default=None, help="tags of the datasets, comma-separated")
    upload.add_argument("--json", action="store_true", help="print the datasets as JSON")
    _add_server(upload)
    upload.set_defaults(handler="service.cli.upload:run_upload")

    submit = sub.add_parser(
        "submit",
        help="evaluate on a loceval service: upload what it lacks, run, download the results",
        description=(
            "Evaluate on a loceval service with the options of `loceval evaluate`: each file "
            "is looked up by its SHA-256 and uploaded only when the service does not hold it "
            "yet; the evaluation's progress is shown and the chosen --formats are downloaded "
            "into --out. Exit codes as `loceval evaluate`. The key of your project comes from "
            "LOCEVAL_API_KEY."
        ),
    )
    add_evaluation_arguments(submit)
    _add_server(submit)
    submit.set_defaults(handler="service.cli.submit:run_submit")


_COMMANDS: Final[tuple[tuple[tuple[str, ...], Callable[[Any], None]], ...]] = (
    (("evaluate",), _add_evaluate),
    (EVO_COMMANDS, add_evo_commands),
    (("inspect", "demo"), _add_inspect_and_demo),
    (("ranging",), _add_ranging),
    (("report",), _add_report),
    (("serve", "worker", "keys", "storage"), _add_service),
    (("upload", "submit"), _add_client),
)
"""Each group of subcommands and the function that adds them, in the help's order."""
