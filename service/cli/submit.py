"""``loceval submit REFERENCE ESTIMATE... --server URL``: ``loceval evaluate`` on a service.

The arguments are ``loceval evaluate``'s (one parser adds them to both,
:func:`service.cli.parser.add_evaluation_arguments`). Each file the evaluation needs (the
sources, and the files of ``--building``, ``--map``, ``--device`` and ``--visits``) is hashed
(SHA-256) and looked up on the service (``GET /datasets?sha256=``); only those it does not hold
are uploaded, resumably (:func:`service.cli.upload.upload_file`). The options go to
``POST /evaluations`` under their keys; the job's progress is shown until it ends; the files
it made (``--formats``) are downloaded into ``--out``. A failed evaluation is the CLI's
one-line error and exit 1, as in ``loceval evaluate`` (both end in :func:`service.cli.main`).
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from loceval.errors import InputError
from loceval.options import AUTO, OPTIONS, OptionKind
from service.cli.output import emit
from service.cli.parser import check_names, systems_of
from service.cli.remote import Server, file_sha256, server_from_args
from service.cli.upload import UploadOptions, chunk_bytes, upload_file

if TYPE_CHECKING:
    import argparse

    from loceval.readers import SourceSpec

__all__ = ["api_options", "flags_named", "run_submit"]

_POLL_S: Final = 0.5
_API_OPTION: Final = re.compile(r"\boptions\.(\w+)")
_DATASET_OPTIONS: Final = frozenset({"building", "map", "device", "visits", "site_matrix"})
"""The options whose CLI value is a local file (the API: an uploaded dataset or the matrix)."""


def run_submit(args: argparse.Namespace) -> int:
    """Upload what the service lacks, evaluate there, show progress, download the results."""
    from loceval.readers import parse_source  # noqa: PLC0415

    check_names(args)
    systems = systems_of(args)
    if args.format:
        msg = "--format does not apply to loceval submit: the service reads each file's format."
        raise InputError(msg)
    ref_spec = parse_source(args.reference)
    est_specs = [parse_source(s) for s in args.estimates]
    for spec in (ref_spec, *est_specs):
        _check_source(spec)
    upload = UploadOptions(chunk_bytes=chunk_bytes(args.chunk_mib), progress=not args.quiet)
    with server_from_args(args.server) as server:
        server.json("GET", "/datasets", params={"limit": 1})  # the server and the key, first
        held = _Datasets(server, upload, quiet=args.quiet)  # stderr: --json's stdout stays clean
        body = {
            "reference": _source(held, ref_spec, args.reference_name),
            "estimates": [
                _source(held, spec, name, system)
                for spec, name, system in zip(
                    est_specs, args.name or [None] * len(est_specs), systems, strict=True
                )
            ],
            "options": api_options(args, held),
        }
        try:
            evaluation = server.json("POST", "/evaluations", json=body)
        except InputError as err:  # the API names options.KEY; the CLI names its flags
            raise err.reworded(flags_named(str(err))) from None
        evaluation = _follow(server, evaluation, quiet=args.quiet)
        if evaluation["status"] != "succeeded":
            error = evaluation.get("error") or {}
            detail = error.get("detail") or "the evaluation failed on the service."
            raise InputError(" ".join(str(detail).split()))
        if args.out is not None:
            _download(server, evaluation, args.out)
        if args.json:
            import json  # noqa: PLC0415

            print(json.dumps(evaluation.get("result"), indent=2, allow_nan=False))  # noqa: T201
        else:
            emit(_summary(evaluation))
            if args.out is not None:
                emit(f"\nArtifacts written to {args.out}")
    if not args.fail_on:
        return 0
    from service.cli.evaluate import document_gate_exit  # noqa: PLC0415  (the gate's code)

    return document_gate_exit(evaluation.get("result") or {}, args)  # exit 3 as evaluate's


def flags_named(text: str) -> str:
    """Return the service's message with each ``options.KEY`` named by its flag (``--max-dt``)."""
    flags = {spec.key: spec.flag for spec in OPTIONS if spec.cli}
    return _API_OPTION.sub(lambda m: flags.get(m.group(1), m.group(0)), text)


def _check_source(spec: SourceSpec) -> None:
    """A source of submit is a file and an optional selector; its format is the service's."""
    if spec.format is not None:
        msg = (
            f"{spec.path}: loceval submit sends the file; the service reads its format "
            "(drop the FORMAT: prefix)."
        )
        raise InputError(msg)
    if spec.options:
        msg = f"{spec.path}: loceval submit takes PATH[@SELECTOR], without KEY=VALUE items."
        raise InputError(msg)
    if not spec.path.is_file():
        msg = f"{str(spec.path)!r} is not a file; loceval submit sends files (zip a bag folder)."
        raise InputError(msg)


class _Datasets:
    """The service's datasets of local files: looked up by SHA-256, uploaded when missing."""

    def __init__(self, server: Server, upload: UploadOptions, *, quiet: bool) -> None:
        self.server = server
        self.upload = upload
        self.quiet = quiet
        self._ids: dict[Path, str] = {}
        self.uploaded: list[str] = []

    def id_of(self, path: Path) -> str:
        """Return the dataset id of a local file (uploading it if the service lacks it)."""
        key = path.resolve()
        if key in self._ids:
            return self._ids[key]
        if not path.is_file():
            msg = f"{str(path)!r} is not a file; loceval submit sends files."
            raise InputError(msg)
        dataset = self.server.dataset_by_sha256(file_sha256(path))
        if dataset is None:
            dataset = upload_file(self.server, path, self.upload)
            self.uploaded.append(str(dataset["id"]))
            said = "uploaded"
        else:
            said = "held by the service"
        if not self.quiet:
            emit(
                f"{path.name}: {said} as dataset {dataset['id']} ({dataset.get('kind')})",
                file=sys.stderr,
            )
        self._ids[key] = str(dataset["id"])
        return self._ids[key]


def _source(
    held: _Datasets, spec: SourceSpec, name: str | None, system: str | None = None
) -> dict[str, Any]:
    """Return the API's source of a local source: its dataset, selector, name and system."""
    source: dict[str, Any] = {"dataset_id": held.id_of(spec.path)}
    if spec.selector is not None:
        source["selector"] = spec.selector
    if name:
        source["name"] = name
    if system:
        source["system"] = system
    return source


def api_options(args: argparse.Namespace, held: _Datasets) -> dict[str, Any]:
    """Return the API's options of the parsed arguments: those given, under their keys.

    Values at their defaults are left to the service; a file option becomes the dataset of
    the file (the device's with its links), and ``--site-matrix FILE`` the matrix it holds.
    """
    options: dict[str, Any] = {}
    for spec in OPTIONS:
        if not (spec.cli and spec.api) or spec.group == "ranging":
            continue
        value = getattr(args, spec.key, None)
        if value is None or value == spec.default:
            continue
        if spec.key in _DATASET_OPTIONS:
            options[spec.key] = _file_option(spec.key, value, args, held)
        elif isinstance(value, tuple | list):
            options[spec.key] = list(value)
        elif spec.kind is OptionKind.SWITCH:
            options[spec.key] = bool(value)
        else:
            options[spec.key] = value
    return options


def _file_option(key: str, value: object, args: argparse.Namespace, held: _Datasets) -> object:
    """Return the API's value of an option whose CLI value names a local file."""
    if value == AUTO:
        return value
    if key == "site_matrix":
        from exporters.cad.site import read_site_matrix  # noqa: PLC0415

        return read_site_matrix(Path(str(value))).as_matrix().tolist()
    if key == "device":
        if not (args.device_from and args.device_to):
            msg = "--device needs --device-from LINK and --device-to LINK."
            raise InputError(msg)
        return {
            "dataset_id": held.id_of(Path(str(value))),
            "from_link": args.device_from,
            "to_link": args.device_to,
        }
    path, _, selector = str(value).partition("@")
    dataset_id = held.id_of(Path(path))
    if key == "map":
        return {"dataset_id": dataset_id, "selector": selector or None}
    return dataset_id


def _follow(server: Server, evaluation: dict[str, Any], *, quiet: bool) -> dict[str, Any]:
    """Poll the evaluation until it ends, with a progress bar of its stage; return it."""
    from tqdm import tqdm  # noqa: PLC0415

    url = f"/evaluations/{evaluation['id']}"
    with tqdm(
        total=100,
        desc="queued",
        disable=quiet,
        file=sys.stderr,
        leave=True,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}",
    ) as bar:
        while evaluation["status"] in {"queued", "running"}:
            time.sleep(_POLL_S)
            evaluation = server.json("GET", url)
            progress = evaluation.get("progress") or {}
            bar.set_description_str(str(progress.get("stage") or evaluation["status"]))
            bar.n = round(100 * float(progress.get("fraction") or 0.0))
            bar.refresh()
        if evaluation["status"] == "succeeded":
            bar.n = 100
            bar.refresh()
    return evaluation


def _download(server: Server, evaluation: dict[str, Any], out: Path) -> None:
    """Download the evaluation's files into ``out`` (their names as the service gives them)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        msg = f"Cannot write into {str(out)!r} ({err.strerror}); name a folder."
        raise InputError(msg) from err
    for artifact in evaluation.get("artifacts") or []:
        name = Path(str(artifact["name"])).name
        server.download(str(artifact["url"]), out / name)


def _summary(evaluation: dict[str, Any]) -> str:
    """Return the headline figures of each estimate, one line each."""
    lines = [f"Evaluation {evaluation['id']} on the service:"]
    for row in evaluation.get("summary") or []:
        ate, rpe = row.get("ate_rmse_m"), row.get("rpe_rmse_m")
        figures = [
            f"ATE RMSE {ate:.4f} m" if isinstance(ate, float) else "ATE RMSE -",
            f"RPE RMSE {rpe:.4f} m" if isinstance(rpe, float) else "RPE RMSE -",
            f"{row.get('matched')} matched",
        ]
        if row.get("verdict"):
            figures.append(str(row["verdict"]))
        lines.append(f"  {row.get('name')}: {', '.join(figures)}")
    return "\n".join(lines)
