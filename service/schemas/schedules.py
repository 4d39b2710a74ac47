"""The HTTP contract of schedules: what a schedule selects, evaluates and produces, its runs."""

from __future__ import annotations

import datetime as dt
import zoneinfo
from typing import Annotated, Any, Final, Literal

from pydantic import BaseModel, Field, field_validator
from pydantic.json_schema import SkipJsonSchema
from pydantic_core import PydanticCustomError

from service.schemas.base import Declared, Id, Printable, Strict
from service.schemas.evaluations import (
    ArtifactPublic,
    EvaluationOptions,
    Problem,
    ProgressPublic,
)

__all__ = [
    "CRON_PATTERN",
    "TIME_ZONES",
    "Cron",
    "EvaluationTemplate",
    "EvoResultRef",
    "Produce",
    "ScheduleCreate",
    "SchedulePatch",
    "SchedulePublic",
    "ScheduleRunPublic",
    "ScheduleRunsPublic",
    "ScheduleWithSecret",
    "SchedulesPublic",
    "Selection",
    "TemplateSource",
]


def _either_case(word: str) -> str:
    return "".join(f"[{c.upper()}{c}]" for c in word)


def _cron_field(low: int, high: int, names: tuple[str, ...] = ()) -> str:
    """Return the pattern of one cron field: ``*``, values, ranges, lists, ``/steps``."""
    value = "|".join([str(i) for i in range(high, low - 1, -1)] + [_either_case(n) for n in names])
    step = "/[1-9][0-9]?"
    item = rf"(\*({step})?|({value})(-({value}))?({step})?)"
    return f"{item}(,{item})*"


CRON_PATTERN: Final = (
    "^ *"
    + " +".join(
        [
            _cron_field(0, 59),
            _cron_field(0, 23),
            _cron_field(1, 31),
            _cron_field(
                1,
                12,
                (
                    "jan",
                    "feb",
                    "mar",
                    "apr",
                    "may",
                    "jun",
                    "jul",
                    "aug",
                    "sep",
                    "oct",
                    "nov",
                    "dec",
                ),
            ),
            _cron_field(0, 7, ("sun", "mon", "tue", "wed", "thu", "fri", "sat")),
        ]
    )
    + " *$"
)
"""The cron lines a schedule takes: five fields (minute hour day month weekday) of numbers in
range, month and day names, ``*``, ranges, lists and steps; croniter's extensions (``L``,
``#``, ``?``, seconds) are not taken. :func:`service.schedules.resource.check_cron` holds
requests to it.
"""

TIME_ZONES: Final = tuple(sorted(zoneinfo.available_timezones()))
"""The IANA time zones a schedule takes (those of this machine's time zone database)."""

Cron = Annotated[
    str,
    Field(min_length=1, max_length=200, examples=["0 7 * * mon"]),
    Declared(
        pattern=CRON_PATTERN,
        description="five fields 'minute hour day month weekday', e.g. '0 7 * * mon' "
        "(Mondays at 07:00); a day of the month that none of the months has (30 in "
        "February only) never fires and is refused",
    ),
]
"""A cron line (checked by :func:`service.schedules.resource.check_cron`, with its message)."""

TimeZone = Annotated[
    str,
    Field(min_length=1, max_length=64, examples=["Europe/Berlin"]),
    Declared(enum=list(TIME_ZONES)),
]
"""An IANA time zone name (checked by :func:`service.schedules.resource.check_cron`)."""


class TemplateSource(Strict):
    """A trajectory in each selected recording: the selector and the name in the report."""

    dataset_id: Id | None = Field(
        default=None,
        description="a fixed dataset used for every recording instead of the recording "
        "itself, e.g. a control-point survey as the reference",
    )
    selector: Annotated[str, Field(min_length=1, max_length=500)] | None = Field(
        default=None, examples=["/amcl_pose", "tf:map:base_link"]
    )
    name: Annotated[str, Field(min_length=1, max_length=120)] | None = None


class EvaluationTemplate(Strict):
    """How each selected recording is evaluated (as ``POST /evaluations``, without ids)."""

    reference: TemplateSource
    estimates: Annotated[list[TemplateSource], Field(min_length=1, max_length=20)]
    options: EvaluationOptions = Field(default_factory=EvaluationOptions)


class EvoResultRef(Strict):
    """An uploaded evo result zip (a dataset of kind ``evo_result``) that joins every run."""

    dataset_id: Id
    name: Annotated[str, Field(min_length=1, max_length=120), Printable] | None = Field(
        default=None,
        description="the system's name in the summary (default: the zip's est_name, a "
        "topic as is, a file by its stem, as loceval names estimates)",
    )


class Selection(Strict):
    """Which recordings a run covers; every given condition must hold.

    Uploaded evo result zips the conditions pick join the run as evo's figures, and so do
    those named in ``evo_results`` (whatever the conditions).
    """

    tags: Annotated[
        list[Annotated[str, Field(min_length=1, max_length=50)]], Field(max_length=20)
    ] = Field(default_factory=list, description="the recording has all of these tags")
    name_pattern: Annotated[str, Field(min_length=1, max_length=200)] | None = Field(
        default=None, description="shell pattern on the name, e.g. 'level2-*'"
    )
    uploaded_within_days: Annotated[float, Field(gt=0, le=3660)] | None = Field(
        default=None, description="uploaded within this many days before the run"
    )
    evo_results: Annotated[list[EvoResultRef], Field(max_length=200)] = Field(
        default_factory=list,
        description="uploaded evo result zips (datasets of kind evo_result) shown in every "
        "run's summary beside the evaluated recordings, their figures marked as evo's",
    )


_SummaryName = Literal["summary.html", "summary.pdf"]


def _both_summaries() -> list[_SummaryName]:
    return ["summary.html", "summary.pdf"]


class Produce(Strict):
    """What a run writes."""

    summary_formats: Annotated[list[_SummaryName], Field(min_length=1, max_length=2)] = Field(
        default_factory=_both_summaries
    )
    per_run_artifacts: bool = Field(
        default=False, description="also write every evaluation's report and CAD files"
    )


_Url = Annotated[str, Field(max_length=2000, pattern=r"^https?://[^\x00-\x20\x7f]+$")]


class ScheduleCreate(Strict):
    """A recurring summary report."""

    name: Annotated[str, Field(min_length=1, max_length=200), Printable]
    cron: Cron
    timezone: TimeZone = "UTC"
    selection: Selection = Field(default_factory=Selection)
    template: EvaluationTemplate
    produce: Produce = Field(default_factory=Produce)
    webhook_url: _Url | None = Field(
        default=None,
        description="receives a signed JSON summary; a public address unless the "
        "administrator allows it (LOCEVAL_WEBHOOK_ALLOW)",
    )
    paused: bool = False


_NOT_NULL: Final = ("name", "cron", "timezone", "selection", "template", "produce", "paused")
"""The fields of a patch that cannot be emptied (absent keeps them; null is refused)."""


def _no_default(schema: dict[str, Any]) -> None:
    """Drop the ``default: null`` of a field that may be absent but never null."""
    schema.pop("default", None)


def _optional(**constraints: Any) -> Any:  # noqa: ANN401  (a pydantic FieldInfo)
    """A patch field that may be absent but not null: absent in the schema's ``required``."""
    return Field(default=None, json_schema_extra=_no_default, **constraints)


class SchedulePatch(Strict):
    """Changes to a schedule; absent fields stay as they are.

    Only ``webhook_url`` may be null (no webhook); a null for another field is refused with
    422 naming it, since a schedule cannot be without a name, a cron line, a selection...
    """

    name: Annotated[str, Field(min_length=1, max_length=200), Printable] | SkipJsonSchema[None] = (
        _optional()
    )
    cron: Cron | SkipJsonSchema[None] = _optional()
    timezone: TimeZone | SkipJsonSchema[None] = _optional()
    selection: Selection | SkipJsonSchema[None] = _optional()
    template: EvaluationTemplate | SkipJsonSchema[None] = _optional()
    produce: Produce | SkipJsonSchema[None] = _optional()
    webhook_url: _Url | None = Field(default=None, description="null removes the webhook")
    paused: bool | SkipJsonSchema[None] = _optional()

    @field_validator(*_NOT_NULL, mode="before")
    @classmethod
    def _not_null(cls, value: Any) -> Any:  # noqa: ANN401
        if value is None:
            msg = "may be left out (it then stays as it is), but not null"
            raise PydanticCustomError("null_refused", msg)  # noqa: EM101  (the error type)
        return value


class SchedulePublic(BaseModel):
    """A schedule and when it fires next."""

    id: str
    name: str
    cron: str
    timezone: str
    paused: bool
    selection: dict[str, Any]
    template: dict[str, Any]
    produce: dict[str, Any]
    webhook_url: str | None
    next_fire_at: dt.datetime | None
    last_fired_at: dt.datetime | None
    created_at: dt.datetime
    updated_at: dt.datetime


class ScheduleWithSecret(SchedulePublic):
    """A schedule with its webhook signing secret: answered once, on create and on rotate."""

    webhook_secret: str = Field(
        description="the key of each delivery's X-Loceval-Signature (HMAC-SHA256 over "
        "'<X-Loceval-Timestamp>.<body>'); shown only now, so store it"
    )


class SchedulesPublic(BaseModel):
    """The project's schedules."""

    items: list[SchedulePublic]
    count: int


class ScheduleRunPublic(BaseModel):
    """One run of a schedule: its recordings, the summary report and the webhook's fate."""

    id: str
    schedule_id: str
    trigger: Literal["cron", "missed", "manual"]
    due_at: dt.datetime
    status: Literal["queued", "running", "succeeded", "failed"]
    progress: ProgressPublic
    note: str | None
    rows: list[dict[str, Any]] | None = Field(
        default=None,
        description=(
            "per recording: dataset, status, error, evaluation_id, summary "
            "(and evaluation_deleted: true once that evaluation was deleted); an uploaded "
            "evo result zip adds source: evo and note (what its figures are), and has no "
            "evaluation_id"
        ),
    )
    error: Problem | None = None
    artifacts: list[ArtifactPublic] | None = None
    webhook: dict[str, Any] | None = None
    attempts: int
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None


class ScheduleRunsPublic(BaseModel):
    """A schedule's runs, newest first."""

    items: list[ScheduleRunPublic]
    count: int
