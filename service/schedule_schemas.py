"""The HTTP contract of schedules: what a schedule selects, evaluates and produces, its runs."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Final, Literal

from pydantic import BaseModel, Field, field_validator
from pydantic.json_schema import SkipJsonSchema
from pydantic_core import PydanticCustomError

from service.schema_base import Id, Printable, Strict
from service.schemas import (
    ArtifactPublic,
    EvaluationOptions,
    Problem,
    ProgressPublic,
)

__all__ = [
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


_Url = Annotated[str, Field(max_length=2000, pattern=r"^https?://[^\s]+$")]


class ScheduleCreate(Strict):
    """A recurring summary report."""

    name: Annotated[str, Field(min_length=1, max_length=200), Printable]
    cron: Annotated[str, Field(min_length=1, max_length=200, examples=["0 7 * * mon"])]
    timezone: Annotated[str, Field(min_length=1, max_length=64, examples=["Europe/Berlin"])] = "UTC"
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
    cron: Annotated[str, Field(min_length=1, max_length=200)] | SkipJsonSchema[None] = _optional()
    timezone: Annotated[str, Field(min_length=1, max_length=64)] | SkipJsonSchema[None] = (
        _optional()
    )
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
