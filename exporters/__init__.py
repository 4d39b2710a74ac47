"""Turn an evaluation result into files: reports, tables and CAD overlays.

Every artifact is produced by one function ``(result, options) -> bytes``; the CLI and the
service look them up in :data:`ARTIFACTS` by file name. Format modules are imported only
when their artifact is asked for, so the CLI starts fast without matplotlib or CAD libraries.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final, Protocol, cast

from exporters.cad.jsondoc import finite_json
from exporters.errors import ExportError, ExportOptionsError, ExportUnavailableError
from exporters.options import ExportOptions, Units
from loceval.evaluation import EvaluationResult, ProgressCallback

if TYPE_CHECKING:
    from exporters.cad.placement import Placement
    from exporters.report import ReportPlots

__all__ = [
    "ARTIFACTS",
    "ARTIFACT_ALIASES",
    "CAD_ARTIFACTS",
    "ArtifactCallback",
    "ArtifactSpec",
    "ExportOptions",
    "Units",
    "artifact_name",
    "export_result_json",
    "render_artifact",
    "write_artifacts",
]


ArtifactCallback = Callable[[str, Path], None]
"""Called with an artifact's name and the path of its finished file, as soon as it is written."""


class Exporter(Protocol):
    """``(result, options) -> bytes``; CAD exporters also take a precomputed ``placement``."""

    def __call__(
        self, result: EvaluationResult, options: ExportOptions, /, **kwargs: Placement
    ) -> bytes:
        """Render the artifact."""
        ...


@dataclass(frozen=True, slots=True)
class ArtifactSpec:
    """One downloadable file of an evaluation.

    Attributes:
        name: the file name (``report.pdf``).
        media_type: its MIME type.
        target: ``"module:function"`` of the exporter, imported on first use.
        requires: the distribution extra that provides its libraries.
    """

    name: str
    media_type: str
    target: str
    requires: str

    def load(self) -> Exporter:
        """Import and return the exporter function.

        Raises:
            ExportUnavailableError: a library the format needs is not installed.
        """
        module_name, _, func_name = self.target.partition(":")
        try:
            module = importlib.import_module(module_name)
        except ImportError as err:
            msg = (
                f"{self.name} needs the Python package {err.name!r}, which is not installed; "
                f"install loceval[{self.requires}] or leave {self.name} out."
            )
            raise ExportUnavailableError(msg) from err
        return cast("Exporter", getattr(module, func_name))


ARTIFACTS: Final[Mapping[str, ArtifactSpec]] = {
    spec.name: spec
    for spec in (
        ArtifactSpec("result.json", "application/json", "exporters:export_result_json", "all"),
        ArtifactSpec("errors.csv", "text/csv", "exporters.tables:export_errors_csv", "all"),
        ArtifactSpec("map_cells.csv", "text/csv", "exporters.mapcells:export_map_cells_csv", "all"),
        ArtifactSpec("report.html", "text/html", "exporters.report:render_report_html", "report"),
        ArtifactSpec(
            "report.pdf", "application/pdf", "exporters.report:render_report_pdf", "report"
        ),
        ArtifactSpec("paths.dxf", "image/vnd.dxf", "exporters.cad.dxf:export_dxf", "cad"),
        ArtifactSpec("paths.3dm", "model/vnd.3dm", "exporters.cad.rhino:export_3dm", "cad"),
        ArtifactSpec(
            "paths.3dm.json", "application/json", "exporters.cad.rhino:export_3dm_json", "cad"
        ),
        ArtifactSpec("paths.glb", "model/gltf-binary", "exporters.cad.gltf:export_glb", "cad"),
        # IFC is an ISO 10303-21 (STEP) file with no IFC-specific registered type: viewers
        # go by the .ifc suffix, and application/x-step makes browsers save it as a file
        ArtifactSpec("paths.ifc", "application/x-step", "exporters.cad.ifc:export_ifc", "cad"),
        # one self-contained page: the interactive 3D and plan viewer (templates/viewer)
        ArtifactSpec("viewer.html", "text/html", "exporters.viewer:export_viewer_html", "all"),
        # what CI systems read (exporters.ci): a JUnit XML test report, a Markdown summary
        ArtifactSpec("junit.xml", "application/xml", "exporters.ci:export_junit_xml", "report"),
        ArtifactSpec("summary.md", "text/markdown", "exporters.ci:export_summary_md", "report"),
    )
}
"""Every artifact, by file name, in the order they are written."""


CAD_ARTIFACTS: Final = frozenset(
    {"paths.dxf", "paths.3dm", "paths.3dm.json", "paths.glb", "paths.ifc"}
)
"""The artifacts that place the paths on the building model."""

ARTIFACT_ALIASES: Final[Mapping[str, str]] = {
    "json": "result.json",
    "csv": "errors.csv",
    "cells": "map_cells.csv",
    "html": "report.html",
    "pdf": "report.pdf",
    "dxf": "paths.dxf",
    "3dm": "paths.3dm",
    "3dm.json": "paths.3dm.json",
    "grasshopper": "paths.3dm.json",
    "glb": "paths.glb",
    "gltf": "paths.glb",
    "ifc": "paths.ifc",
    "viewer": "viewer.html",
    "junit": "junit.xml",
    "markdown": "summary.md",
    "md": "summary.md",
}
"""Format names a user may give instead of file names (``dxf`` for ``paths.dxf``)."""


def artifact_name(text: str) -> str:
    """Return the artifact file name that ``text`` names: a file name or a format alias.

    Case and surrounding spaces do not matter, and a leading dot is allowed (``.DXF``).

    Raises:
        ExportOptionsError: neither an artifact nor an alias; the message lists both.
    """
    key = text.strip().lower()
    if key in ARTIFACTS:
        return key
    alias = ARTIFACT_ALIASES.get(key.removeprefix("."))
    if alias is not None:
        return alias
    aliases = ", ".join(f"{a} ({n})" for a, n in ARTIFACT_ALIASES.items())
    msg = (
        f"No output format named {text!r}; choose file names from {', '.join(ARTIFACTS)} "
        f"or formats from {aliases}."
    )
    raise ExportOptionsError(msg, option="formats")


def export_result_json(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    cad: Mapping[str, object] | None = None,
) -> bytes:
    """Return the ``--json`` document, with the evaluation id, as UTF-8 bytes.

    Args:
        result: the evaluation.
        options: the export options (for the evaluation id).
        cad: the placement of the CAD files written beside it (units, site, base point,
            simplification tolerance and the largest deviation it introduced), if any.
    """
    document = {"evaluation_id": options.evaluation_id, **result.to_dict()}
    if cad is not None:
        document["cad"] = dict(cad)
    return (finite_json(document, indent=2) + "\n").encode()


def render_artifact(name: str, result: EvaluationResult, options: ExportOptions) -> bytes:
    """Produce one artifact by file name.

    Raises:
        ExportOptionsError: the name is not an artifact.
        ExportUnavailableError: its libraries are not installed.
        ExportError: the exporter failed.
    """
    return _artifact(name).load()(_on_building(result, options), options)


def _on_building(result: EvaluationResult, options: ExportOptions) -> EvaluationResult:
    """Return the result placed on the options' building (its rooms, its warnings), once.

    Every artifact of a run then names the same rooms (``result.json``, the report, the
    viewer); the CAD libraries are loaded only when there is a building.
    """
    if options.building is None:
        return result
    from exporters.cad.spaces import placed_on_building  # noqa: PLC0415  (CAD libraries)

    return placed_on_building(result, options)


def _artifact(name: str) -> ArtifactSpec:
    """Return the artifact called ``name``, or raise ExportOptionsError listing them all."""
    spec = ARTIFACTS.get(name)
    if spec is None:
        msg = f"No artifact named {name!r}; choose from {', '.join(ARTIFACTS)}."
        raise ExportOptionsError(msg)
    return spec


def write_artifacts(
    result: EvaluationResult,
    out_dir: Path,
    options: ExportOptions,
    *,
    names: Iterable[str] | None = None,
    progress: ProgressCallback | None = None,
    on_written: ArtifactCallback | None = None,
) -> list[Path]:
    """Write artifacts into ``out_dir``, all or nothing.

    Everything is rendered into a staging folder beside ``out_dir`` first and moved into
    place only when every artifact succeeded, so a failure leaves no half-written files.
    ``on_written`` sees each file the moment it is complete in the staging folder (the
    service shows an evaluation's figures before its reports are laid out); the file
    stays there until every artifact is written, then moves to ``out_dir``.

    Args:
        result: the evaluation.
        out_dir: the destination folder (created if missing).
        options: placement and report options.
        names: the artifacts to write (default: all of :data:`ARTIFACTS`).
        progress: called with (stage, fraction done) before each artifact.
        on_written: called with the name and the staged path of each finished artifact,
            in the order they are written (``result.json`` first when it is wanted).

    Returns:
        The paths written.

    Raises:
        ExportError: an artifact could not be produced (nothing is moved into place).
        ExportOptionsError: an unknown artifact name.
    """
    wanted = list(ARTIFACTS) if names is None else list(dict.fromkeys(names))
    for name in wanted:
        _artifact(name)  # every name is checked before anything is rendered
    import shutil  # noqa: PLC0415  (loaded when artifacts are written, not for --json)

    out_dir = out_dir.resolve()
    staging = _staging_folder(out_dir)
    try:
        _render_into(
            staging, result, options, wanted, progress or _no_progress, on_written=on_written
        )
        out_dir.mkdir(exist_ok=True)
        written = []
        for name in wanted:
            (staging / name).replace(out_dir / name)
            written.append(out_dir / name)
    except OSError as err:
        msg = (
            f"Cannot write the artifacts into {str(out_dir)!r} ({err.strerror}); check the "
            "free space and permissions, or name another folder."
        )
        raise ExportError(msg) from err
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return written


def _staging_folder(out_dir: Path) -> Path:
    """Create the hidden folder beside ``out_dir`` that artifacts are rendered into."""
    if out_dir.exists() and not out_dir.is_dir():
        msg = (
            f"The artifact folder {str(out_dir)!r} is a file, not a folder; name a folder for "
            "the artifacts."
        )
        raise ExportOptionsError(msg)
    import tempfile  # noqa: PLC0415  (loaded when artifacts are written, not for --json)

    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    except OSError as err:
        msg = (
            f"Cannot create the artifact folder {str(out_dir)!r} ({err.strerror}); name a "
            "folder you can write to."
        )
        raise ExportError(msg) from err


def _no_progress(_stage: str, _fraction: float) -> None:
    """Ignore progress."""


def _render_into(
    staging: Path,
    result: EvaluationResult,
    options: ExportOptions,
    wanted: list[str],
    progress: ProgressCallback,
    *,
    on_written: ArtifactCallback | None = None,
) -> None:
    """Render every wanted artifact into ``staging``, placing the CAD paths only once."""
    result = _on_building(result, options)
    placement = None
    if CAD_ARTIFACTS.intersection(wanted):
        # Placing (site transform, units, simplification) is shared by every CAD file.
        from exporters.cad.placement import place_evaluation  # noqa: PLC0415

        placement = place_evaluation(result, options)
    reports = _ReportFigures(result, options, wanted)
    for k, name in enumerate(wanted):
        progress(f"writing {name}", k / len(wanted))
        if placement is not None and name == "result.json":
            data = export_result_json(result, options, cad=placement.metadata())
        elif placement is not None and name in CAD_ARTIFACTS:
            data = ARTIFACTS[name].load()(result, options, placement=placement)
        elif name in _REPORTS:
            data = reports.render(name)
        else:
            data = render_artifact(name, result, options)
        (staging / name).write_bytes(data)
        if on_written is not None:
            on_written(name, staging / name)


_REPORTS: Final = frozenset({"report.html", "report.pdf"})
"""The artifacts that embed the report's figures (SVG in both; PNG in a WeasyPrint PDF)."""


class _ReportFigures:
    """Renders ``report.html`` and ``report.pdf`` of one run, drawing each figure once.

    When a run writes both reports, every figure is drawn once and encoded in the formats
    the two embed (SVG for both with the repository's templates; SVG and PNG when a folder
    of one's own has its PDF laid out by WeasyPrint); a run writing one draws only its own.
    """

    def __init__(self, result: EvaluationResult, options: ExportOptions, wanted: list[str]) -> None:
        self._result = result
        self._options = options
        self._wanted = _REPORTS.intersection(wanted)
        self._plots: ReportPlots | None = None

    def render(self, name: str) -> bytes:
        """Render the report ``name`` (``report.html`` or ``report.pdf``)."""
        spec = ARTIFACTS[name]
        spec.load()  # the libraries' message (ExportUnavailableError) when one is missing
        from exporters.report import (  # noqa: PLC0415  (matplotlib, Jinja2)
            DEFAULT_TEMPLATES_DIR,
            render_report_html,
            render_report_pdf,
            render_report_plots,
            report_figure_formats,
        )

        if self._plots is None:
            folder = self._options.templates_dir or DEFAULT_TEMPLATES_DIR
            formats = report_figure_formats(folder, self._wanted)
            self._plots = render_report_plots(self._result, self._options, formats=formats)
        if name == "report.html":
            return render_report_html(self._result, self._options, plots=self._plots)
        return render_report_pdf(self._result, self._options, plots=self._plots)


__all__ += ["ExportError", "ExportOptionsError", "ExportUnavailableError"]
