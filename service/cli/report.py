"""``loceval report``: one summary report over many recordings, as a schedule run makes it.

The template is the API's ``EvaluationTemplate`` (validated by pydantic, so its options are
the API's, named ``options.<key>`` in messages). A result zip of evo_ape/evo_rpe among the
files is not evaluated: its figures join the summary marked as evo's, as a schedule does.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import TYPE_CHECKING, Any

from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.errors import InputError, LocevalError
from loceval.readers import SourceSpec
from loceval.readers.evo_result import is_result_zip, read_result_zip
from service.cli.output import emit
from service.jobs.options import config_from_options
from service.jobs.runner import (
    Job,
    JobSource,
    default_name,
    evaluation_job,
    file_provenance,
    run_job,
)

if TYPE_CHECKING:
    import argparse

    from loceval.evaluation import EvaluationConfig
    from service.schemas.schedules import EvaluationTemplate, TemplateSource

__all__ = ["run_report"]


def run_report(args: argparse.Namespace) -> int:
    """Evaluate each recording with the template and write the summary files asked for.

    ``--formats`` picks summary.html, summary.pdf or both (the default). The formats and the
    template are checked first; then, before any recording is evaluated, whether a PDF can
    be made (Typst, with the repository's templates; HTML templates of one's own need
    WeasyPrint and pango): when it cannot, the command stops there and says how to write
    the HTML alone.
    """
    from exporters.summary import SummaryRun, summary_formats  # noqa: PLC0415
    from service.schedules.summaries import summary_files  # noqa: PLC0415

    formats = summary_formats(args.formats)
    template = _read_template(args.template)
    options = template.options
    try:
        config = config_from_options(options)
    except LocevalError as err:  # the same error (its class and code), in the template's words
        msg = f"The template {str(args.template)!r}: {_api_words(err)}"
        raise err.reworded(msg) from err
    if "summary.pdf" in formats:  # after the user's input is checked, before the work
        _check_pdf()
    runs = []
    for path in args.datasets:
        recorded = (
            dt.datetime.fromtimestamp(path.stat().st_mtime, dt.UTC)
            if path.exists()
            else (dt.datetime.now(dt.UTC))
        )
        if is_result_zip(path):  # an evo result: its figures, not a recording to evaluate
            runs.append(_evo_run(path, recorded))
            continue
        job = _template_job(path, template, config)
        try:
            result = run_job(job, None)
        except LocevalError as err:
            runs.append(SummaryRun(path.name, recorded, "failed", error=_api_words(err)))
            continue
        runs.append(
            SummaryRun.from_result(
                result.to_dict(),
                dataset=path.name,
                recorded_at=recorded,
                # control points have no reference path to compare across runs
                reference_xyz=None
                if isinstance(result, CheckpointEvaluation)
                else result.reference.positions_xyz,
                reference_t_s=None
                if isinstance(result, CheckpointEvaluation)
                else result.reference.stamps_ns / 1e9,
            )
        )
    from service.settings import Settings  # noqa: PLC0415

    files = summary_files(
        template,
        runs,
        formats,
        title=args.title,
        selection=f"the {len(args.datasets)} recordings named on the command line",
        templates_dir=Settings().templates_dir,
    )
    _write_all(args.out, files)
    for run in runs:
        figures = ", ".join(
            f"{name} ATE {fig.ate_rmse_m:.3f} m" if fig.ate_rmse_m is not None else name
            for name, fig in run.systems.items()
        )
        emit(f"{run.dataset}: {run.status}" + (f" ({run.error})" if run.error else f", {figures}"))
    emit(f"\nSummary written to {args.out}")
    return 0


def _evo_run(path: Path, modified: dt.datetime) -> Any:  # noqa: ANN401  (a SummaryRun)
    """Return an evo result zip as a summary run (evo's figures), or as failed with the reason.

    Dated by its first error stamp when that is a date, else by the file's time (marked).
    """
    from exporters.summary import SummaryRun  # noqa: PLC0415
    from exporters.summary.evo import evo_summary_run  # noqa: PLC0415
    from service.schedules.runs import recording_start  # noqa: PLC0415

    try:
        result = read_result_zip(path)
    except InputError as err:
        return SummaryRun(path.name, modified, "failed", error=str(err), source="evo")
    first_s = result.first_stamp_s
    recorded, is_upload = recording_start({} if first_s is None else {"start_s": first_s}, modified)
    return evo_summary_run(
        result, dataset=path.name, recorded_at=recorded, recorded_at_is_upload=is_upload
    )


def _check_pdf() -> None:
    """Stop before the evaluations if no PDF can be made, naming the HTML-only way out."""
    from exporters.errors import ExportUnavailableError  # noqa: PLC0415
    from exporters.report import check_pdf  # noqa: PLC0415
    from exporters.summary.render import SUMMARY_PDF_TEMPLATE_NAME  # noqa: PLC0415
    from service.settings import Settings  # noqa: PLC0415

    try:
        check_pdf(Settings().templates_dir, SUMMARY_PDF_TEMPLATE_NAME)
    except ExportUnavailableError as err:
        # the CLI shows it as "--formats: ... Use --formats summary.html."
        raise ExportUnavailableError(str(err), option="formats", suggest="summary.html") from err


def _api_words(err: LocevalError) -> str:
    """Name the option at fault as the template does (``options.max_dt_s: ...``)."""
    return str(err) if err.option is None else f"options.{err.option}: {err}"


def _read_template(path: Path) -> EvaluationTemplate:
    from pydantic import ValidationError  # noqa: PLC0415

    from service.schemas.schedules import EvaluationTemplate  # noqa: PLC0415

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"Cannot read the template {str(path)!r} ({err}); check the path."
        raise InputError(msg) from err
    try:
        return EvaluationTemplate.model_validate_json(text)
    except ValidationError as err:
        where = "; ".join(
            f"{'.'.join(str(p) for p in e['loc']) or 'template'}: {e['msg']}"
            for e in err.errors()[:5]
        )
        msg = f"The template {str(path)!r} is not valid: {where}."
        raise InputError(msg) from None


def _template_job(path: Path, template: EvaluationTemplate, config: EvaluationConfig) -> Job:
    """Return the job of one recording: the template's sources read from ``path``."""

    def source(entry: TemplateSource, role: str) -> JobSource:
        if entry.dataset_id is not None:
            msg = (
                f"The template's {role} names the dataset {entry.dataset_id!r}, an upload of "
                "the service; the report command reads the recordings named, so leave it out."
            )
            raise InputError(msg)
        spec = SourceSpec(None, path, entry.selector)
        name = entry.name or default_name(spec)
        return JobSource(spec, name, file_provenance(role, spec))

    return evaluation_job(
        reference=source(template.reference, "reference"),
        estimates=[source(e, "estimate") for e in template.estimates],
        config=config,
        stamp=template.options.stamp,
    )


def _write_all(out: Path, files: dict[str, bytes]) -> None:
    """Write the files into ``out`` through temporary names: each appears whole or not at all."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            partial = out / f".{name}.partial"
            partial.write_bytes(data)
            partial.replace(out / name)
    except OSError as err:
        msg = f"Cannot write into {str(out)!r} ({err.strerror}); name a folder you can write to."
        raise InputError(msg) from err
