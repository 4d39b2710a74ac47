"""The HTTP contract: request and response bodies (``XCreate`` / ``XPublic`` / ``XsPublic``)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from exporters import ARTIFACTS
from loceval.metrics import DEFAULT_THRESHOLDS_M

__all__ = [
    "ArtifactPublic",
    "DatasetPublic",
    "DatasetsPublic",
    "DeviceOffset",
    "EvaluationCreate",
    "EvaluationOptions",
    "EvaluationPublic",
    "EvaluationTemplate",
    "EvaluationsPublic",
    "Problem",
    "Produce",
    "ProgressPublic",
    "ScheduleCreate",
    "SchedulePatch",
    "SchedulePublic",
    "ScheduleRunPublic",
    "ScheduleRunsPublic",
    "SchedulesPublic",
    "Selection",
    "SourceRef",
    "SummaryRow",
    "TemplateSource",
]

_Id = Annotated[str, Field(min_length=1, max_length=64, examples=["0b8e6c1e-..."])]
_Finite = Annotated[float, Field(allow_inf_nan=False)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Problem(BaseModel):
    """An error, as ``application/problem+json`` (RFC 9457)."""

    model_config = ConfigDict(extra="allow")

    type: str = Field(examples=["input.unreadable"])
    title: str = Field(examples=["ReaderError"])
    status: int = Field(examples=[422])
    detail: str = Field(examples=["run.mcap: no topic '/odom'; the bag has /amcl_pose, /tf."])


class SourceRef(_Strict):
    """A trajectory in an uploaded dataset."""

    dataset_id: _Id
    selector: Annotated[str, Field(min_length=1, max_length=500)] | None = Field(
        default=None,
        description="topic, tf:PARENT:CHILD or rigid body; null for a plain trajectory file",
        examples=["/amcl_pose", "tf:map:base_link"],
    )
    name: Annotated[str, Field(min_length=1, max_length=120)] | None = Field(
        default=None, description="name in the report (default: selector or file name)"
    )


class DeviceOffset(_Strict):
    """The rigid body -> sensor offset read from an uploaded URDF or bag (``/tf_static``)."""

    dataset_id: _Id
    from_link: Annotated[str, Field(min_length=1, max_length=200)]
    to_link: Annotated[str, Field(min_length=1, max_length=200)]


class EvaluationOptions(_Strict):
    """The CLI's options (``loceval evaluate --help``), with the same defaults."""

    association: Literal["interpolate", "nearest"] = "interpolate"
    max_dt_s: Annotated[_Finite, Field(gt=0, le=3600)] = 0.01
    max_gap_s: Annotated[_Finite, Field(gt=0, le=1e6)] = 0.1
    time_offset_s: Annotated[_Finite, Field(ge=-1e9, le=1e9)] = 0.0
    stamp: Literal["header", "receive"] = "header"
    align: Literal["se3", "sim3", "origin", "yaw", "calibrate", "none"] = "se3"
    align_first: (
        Annotated[str, Field(pattern=r"^\s*\d+(\.\d+)?\s*s?\s*$", max_length=32)] | None
    ) = Field(default=None, description="align on the first N poses or N seconds (10s)")
    calibrate_at_s: Annotated[_Finite, Field(ge=0, le=1e9)] | None = None
    offset: Annotated[str, Field(max_length=300)] | None = Field(
        default=None, description='rigid body -> sensor "x y z qx qy qz qw"'
    )
    device: DeviceOffset | None = None
    rpe_delta: Annotated[_Finite, Field(gt=0, le=1e9)] = 1.0
    rpe_unit: Literal["frames", "m", "s"] = "frames"
    rpe_all_pairs: bool = False
    thresholds_m: Annotated[list[Annotated[_Finite, Field(gt=0, le=1e6)]], Field(max_length=20)] = (
        Field(default_factory=lambda: list(DEFAULT_THRESHOLDS_M))
    )
    tolerance: Annotated[str, Field(max_length=40, examples=["0.10@95"])] | None = None
    worst: Annotated[int, Field(ge=0, le=1000)] = 10
    units: Literal["mm", "cm", "m"] = "mm"
    site: Annotated[str, Field(max_length=200, examples=["12.5 3.2 0 90"])] | None = None
    site_matrix: (
        Annotated[
            list[Annotated[list[_Finite], Field(min_length=4, max_length=4)]],
            Field(min_length=4, max_length=4),
        ]
        | None
    ) = None
    simplify_m: Annotated[_Finite, Field(ge=0, le=1000)] = 0.001
    formats: (
        Annotated[
            list[Annotated[str, Field(max_length=40, json_schema_extra={"enum": list(ARTIFACTS)})]],
            Field(min_length=1, max_length=20),
        ]
        | None
    ) = Field(default=None, description=f"artifacts to write (default: all of {list(ARTIFACTS)})")

    @field_validator("formats")
    @classmethod
    def _known_formats(cls, value: list[str] | None) -> list[str] | None:
        unknown = [v for v in value or [] if v not in ARTIFACTS]
        if unknown:
            msg = f"unknown artifact {unknown[0]!r}; choose from {', '.join(ARTIFACTS)}"
            raise ValueError(msg)
        return value


class EvaluationCreate(_Strict):
    """A new evaluation: a reference, the estimates, and options."""

    reference: SourceRef
    estimates: Annotated[list[SourceRef], Field(min_length=1, max_length=20)]
    options: EvaluationOptions = Field(default_factory=EvaluationOptions)


class DatasetPublic(BaseModel):
    """An uploaded recording and what it holds."""

    id: str
    name: str
    filename: str
    kind: str = Field(examples=["rosbag2-mcap"])
    size_bytes: int
    sha256: str
    tags: list[str]
    created_at: dt.datetime
    inspection: dict[str, Any] = Field(
        description="kind, sources (selector, description, pose_count, ...), topics, tf_tree"
    )


class DatasetsPublic(BaseModel):
    """A page of datasets, newest first."""

    items: list[DatasetPublic]
    count: int


class ProgressPublic(BaseModel):
    """Where a job is."""

    stage: str
    fraction: float


class SummaryRow(BaseModel):
    """Headline figures of one estimate."""

    name: str | None
    ate_rmse_m: float | None
    rpe_rmse_m: float | None
    matched: int | None
    verdict: Literal["pass", "fail"] | None


class ArtifactPublic(BaseModel):
    """A downloadable file of a succeeded evaluation."""

    name: str
    media_type: str
    size_bytes: int
    url: str


class EvaluationPublic(BaseModel):
    """An evaluation job: status, progress, and the result once it succeeded."""

    id: str
    status: Literal["queued", "running", "succeeded", "failed"]
    progress: ProgressPublic
    attempts: int
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    reference: SourceRef
    estimates: list[SourceRef]
    options: dict[str, Any]
    summary: list[SummaryRow] | None = None
    error: Problem | None = None
    artifacts: list[ArtifactPublic] | None = None
    result: dict[str, Any] | None = Field(
        default=None, description="the CLI's --json document (GET of one evaluation only)"
    )


class EvaluationsPublic(BaseModel):
    """A page of evaluations, newest first (without the result documents)."""

    items: list[EvaluationPublic]
    count: int


# --- schedules ---------------------------------------------------------------------------


class TemplateSource(_Strict):
    """A trajectory in each selected recording: the selector and the name in the report."""

    selector: Annotated[str, Field(min_length=1, max_length=500)] | None = Field(
        default=None, examples=["/amcl_pose", "tf:map:base_link"]
    )
    name: Annotated[str, Field(min_length=1, max_length=120)] | None = None


class EvaluationTemplate(_Strict):
    """How each selected recording is evaluated (as ``POST /evaluations``, without ids)."""

    reference: TemplateSource
    estimates: Annotated[list[TemplateSource], Field(min_length=1, max_length=20)]
    options: EvaluationOptions = Field(default_factory=EvaluationOptions)


class Selection(_Strict):
    """Which recordings a run covers; every given condition must hold."""

    tags: Annotated[
        list[Annotated[str, Field(min_length=1, max_length=50)]], Field(max_length=20)
    ] = Field(default_factory=list, description="the recording has all of these tags")
    name_pattern: Annotated[str, Field(min_length=1, max_length=200)] | None = Field(
        default=None, description="shell pattern on the name, e.g. 'level2-*'"
    )
    uploaded_within_days: Annotated[float, Field(gt=0, le=3660)] | None = Field(
        default=None, description="uploaded within this many days before the run"
    )


_SummaryName = Literal["summary.html", "summary.pdf"]


def _both_summaries() -> list[_SummaryName]:
    return ["summary.html", "summary.pdf"]


class Produce(_Strict):
    """What a run writes."""

    summary_formats: Annotated[list[_SummaryName], Field(min_length=1, max_length=2)] = Field(
        default_factory=_both_summaries
    )
    per_run_artifacts: bool = Field(
        default=False, description="also write every evaluation's report and CAD files"
    )


_Url = Annotated[str, Field(max_length=2000, pattern=r"^https?://[^\s]+$")]


class ScheduleCreate(_Strict):
    """A recurring summary report."""

    name: Annotated[str, Field(min_length=1, max_length=200)]
    cron: Annotated[str, Field(min_length=1, max_length=200, examples=["0 7 * * mon"])]
    timezone: Annotated[str, Field(min_length=1, max_length=64, examples=["Europe/Berlin"])] = "UTC"
    selection: Selection = Field(default_factory=Selection)
    template: EvaluationTemplate
    produce: Produce = Field(default_factory=Produce)
    webhook_url: _Url | None = Field(default=None, description="receives a JSON summary")
    paused: bool = False


class SchedulePatch(_Strict):
    """Changes to a schedule; absent fields stay as they are."""

    name: Annotated[str, Field(min_length=1, max_length=200)] | None = None
    cron: Annotated[str, Field(min_length=1, max_length=200)] | None = None
    timezone: Annotated[str, Field(min_length=1, max_length=64)] | None = None
    selection: Selection | None = None
    template: EvaluationTemplate | None = None
    produce: Produce | None = None
    webhook_url: _Url | None = None
    paused: bool | None = None


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
        default=None, description="per recording: dataset, status, error, evaluation_id, summary"
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
