"""Metadata tables (SQLAlchemy 2) and the engine; the schema is owned by Alembic migrations.

Blobs (uploads, artifacts) live in :mod:`service.blobs`; rows here point at them by path
relative to the data directory, so the same rows work on every machine that mounts it.
"""

from __future__ import annotations

import datetime as dt
import enum
import uuid
from pathlib import Path
from typing import Any, Final, TypeVar

from alembic import command
from alembic.config import Config
from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Dialect,
    Engine,
    Float,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
    create_engine,
    event,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column, sessionmaker

from service.errors import NotFoundError
from service.webhooks import new_secret

__all__ = [
    "ACTIVE_STATUSES",
    "ApiKey",
    "Base",
    "Dataset",
    "Evaluation",
    "EvaluationStatus",
    "JobState",
    "JobStatus",
    "Project",
    "Schedule",
    "ScheduleRun",
    "TusUpload",
    "create_db_engine",
    "get_owned",
    "make_session_factory",
    "migrate",
    "new_id",
    "utcnow",
]

_MIGRATIONS: Final = Path(__file__).resolve().parent / "migrations"


def new_id() -> str:
    """Return a new random row id (a UUID4 as text)."""
    return str(uuid.uuid4())


def utcnow() -> dt.datetime:
    """Return the current time, timezone-aware UTC."""
    return dt.datetime.now(dt.UTC)


class UTCDateTime(TypeDecorator[dt.datetime]):
    """A timestamp stored as UTC and always read back timezone-aware (SQLite drops zones)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: dt.datetime | None, dialect: Dialect) -> dt.datetime | None:
        """Store naive-free UTC."""
        del dialect
        if value is None:
            return None
        if value.tzinfo is None:
            msg = "naive datetime stored; use service.db.utcnow()"
            raise ValueError(msg)
        return value.astimezone(dt.UTC)

    def process_result_value(
        self, value: dt.datetime | None, dialect: Dialect
    ) -> dt.datetime | None:
        """Read back as UTC."""
        del dialect
        if value is None:
            return None
        return value.replace(tzinfo=dt.UTC) if value.tzinfo is None else value.astimezone(dt.UTC)


class Base(DeclarativeBase):
    """Declarative base of every table."""

    type_annotation_map: Final = {
        dt.datetime: UTCDateTime(),
        dict[str, Any]: JSON(),
        list[Any]: JSON(),
    }


class Project(Base):
    """A site or team: owns keys, datasets and evaluations."""

    __tablename__ = "projects"

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)


class ApiKey(Base):
    """An API key, stored as its SHA-256 (keys are 256-bit random, so no slow hash is needed)."""

    __tablename__ = "api_keys"

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    project_id: Mapped[str] = mapped_column(ForeignKey("projects.id", ondelete="CASCADE"))
    prefix: Mapped[str] = mapped_column(String(16))
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    revoked_at: Mapped[dt.datetime | None] = mapped_column(default=None)


class Dataset(Base):
    """An uploaded recording; the file is at ``data_dir / storage_path``."""

    __tablename__ = "datasets"
    __table_args__ = (
        UniqueConstraint("project_id", "sha256", name="uq_datasets_project_sha256"),
        Index("ix_datasets_project_created", "project_id", "created_at"),
    )

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    project_id: Mapped[str] = mapped_column(ForeignKey("projects.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(300))
    filename: Mapped[str] = mapped_column(String(300))
    kind: Mapped[str] = mapped_column(String(40))
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    sha256: Mapped[str] = mapped_column(String(64))
    tags: Mapped[list[Any]] = mapped_column(default=list)
    inspection: Mapped[dict[str, Any]] = mapped_column(default=dict)
    storage_path: Mapped[str] = mapped_column(Text)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)


class TusUpload(Base):
    """A resumable upload (tus 1.0, :mod:`service.uploads.tus`): its offset and its parts' state.

    The bytes lie in the blob store (:mod:`service.blobs.resumable`); this row is the truth
    about how many of them count, so any replica continues where another stopped. Once
    complete, ``dataset_id`` names the dataset it became (or ``error`` why none).
    """

    __tablename__ = "tus_uploads"
    __table_args__ = (Index("ix_tus_uploads_expires", "expires_at"),)

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    project_id: Mapped[str] = mapped_column(ForeignKey("projects.id", ondelete="CASCADE"))
    length: Mapped[int] = mapped_column(BigInteger)
    offset: Mapped[int] = mapped_column("upload_offset", BigInteger, default=0)
    filename: Mapped[str] = mapped_column(Text, default="")
    name: Mapped[str | None] = mapped_column(Text, default=None)
    tags: Mapped[list[Any]] = mapped_column(default=list)
    metadata_header: Mapped[str] = mapped_column(Text, default="")
    """The ``Upload-Metadata`` as sent (HEAD answers it back)."""
    state: Mapped[dict[str, Any]] = mapped_column(default=dict)
    """The backend's state of the parts (:class:`service.blobs.resumable.ResumableParts`)."""
    dataset_id: Mapped[str | None] = mapped_column(String(36), default=None)
    report: Mapped[dict[str, Any] | None] = mapped_column(default=None)
    """What became of the upload (the ``upload`` notes of ``POST /datasets``)."""
    error: Mapped[dict[str, Any] | None] = mapped_column(default=None)
    """The problem document of a complete upload that could not become a dataset."""
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[dt.datetime] = mapped_column()


class JobStatus(enum.StrEnum):
    """The states of a queued job (an evaluation or a schedule run); the values are stored."""

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


ACTIVE_STATUSES: Final = frozenset({JobStatus.QUEUED, JobStatus.RUNNING})
"""The states of a job that has not finished."""

EvaluationStatus = JobStatus
"""The former name of :class:`JobStatus`, kept for code written against it."""


class JobState:
    """The columns of a queued job, shared by evaluations and schedule runs.

    The job functions in :mod:`service.jobs.tracking` (claim, progress, heartbeat, finish, recovery)
    work on either table through these columns.
    """

    status: Mapped[str] = mapped_column(String(16), default=JobStatus.QUEUED)
    stage: Mapped[str] = mapped_column(String(200), default="queued")
    fraction: Mapped[float] = mapped_column(Float, default=0.0)
    error: Mapped[dict[str, Any] | None] = mapped_column(default=None)
    artifacts: Mapped[list[Any] | None] = mapped_column(default=None)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    worker: Mapped[str | None] = mapped_column(String(200), default=None)
    heartbeat_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    started_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    finished_at: Mapped[dt.datetime | None] = mapped_column(default=None)


class Evaluation(JobState, Base):
    """An evaluation job and, once it succeeded, its result and artifacts."""

    __tablename__ = "evaluations"
    __table_args__ = (
        Index("ix_evaluations_project_created", "project_id", "created_at"),
        Index("ix_evaluations_status", "status"),
    )

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    project_id: Mapped[str] = mapped_column(ForeignKey("projects.id", ondelete="CASCADE"))
    kind: Mapped[str] = mapped_column(String(32), default="trajectory")
    """The kind of its request (:data:`service.jobs.kinds.REQUEST_KINDS`), read with it."""
    request: Mapped[dict[str, Any]] = mapped_column()
    dataset_ids: Mapped[list[Any]] = mapped_column(default=list)
    result: Mapped[dict[str, Any] | None] = mapped_column(default=None)
    summary: Mapped[list[Any] | None] = mapped_column(default=None)


class Schedule(Base):
    """A recurring summary report over the project's recordings."""

    __tablename__ = "schedules"
    __table_args__ = (Index("ix_schedules_due", "paused", "next_fire_at"),)

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    project_id: Mapped[str] = mapped_column(ForeignKey("projects.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(200))
    cron: Mapped[str] = mapped_column(String(200))
    timezone: Mapped[str] = mapped_column(String(64))
    paused: Mapped[bool] = mapped_column(Boolean, default=False)
    selection: Mapped[dict[str, Any]] = mapped_column()
    template: Mapped[dict[str, Any]] = mapped_column()
    produce: Mapped[dict[str, Any]] = mapped_column()
    webhook_url: Mapped[str | None] = mapped_column(Text, default=None)
    webhook_secret: Mapped[str] = mapped_column(String(64), default=new_secret)
    """The key of the webhook's HMAC signature (:mod:`service.webhooks`); never listed."""
    next_fire_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    last_fired_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[dt.datetime] = mapped_column(default=utcnow)


class ScheduleRun(JobState, Base):
    """One firing of a schedule: its evaluations, the summary report and the webhook."""

    __tablename__ = "schedule_runs"
    __table_args__ = (
        UniqueConstraint("schedule_id", "due_at", name="uq_schedule_runs_due"),
        Index("ix_schedule_runs_schedule_created", "schedule_id", "created_at"),
    )

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_id)
    schedule_id: Mapped[str] = mapped_column(ForeignKey("schedules.id", ondelete="CASCADE"))
    project_id: Mapped[str] = mapped_column(ForeignKey("projects.id", ondelete="CASCADE"))
    trigger: Mapped[str] = mapped_column(String(16))
    due_at: Mapped[dt.datetime] = mapped_column()
    note: Mapped[str | None] = mapped_column(Text, default=None)
    rows: Mapped[list[Any] | None] = mapped_column(default=None)
    webhook: Mapped[dict[str, Any] | None] = mapped_column(default=None)


_Owned = TypeVar("_Owned", Dataset, Evaluation, Schedule)


def get_owned(
    sessions: sessionmaker[Session], model: type[_Owned], row_id: str, project_id: str
) -> _Owned:
    """Return a dataset, evaluation or schedule of the project.

    Raises:
        NotFoundError: no such row in this project (another project's ids included, so
            their existence is not revealed).
    """
    row = None
    if "\x00" not in row_id:  # no id holds NUL, and PostgreSQL cannot compare one
        with sessions() as session:
            row = session.get(model, row_id)
    if row is None or row.project_id != project_id:
        plural = str(model.__tablename__)
        msg = f"No {plural[:-1]} {row_id!r} in this project; list them with GET /{plural}."
        raise NotFoundError(msg)
    return row


def create_db_engine(url: str) -> Engine:
    """Return an engine; SQLite gets WAL, a busy timeout and foreign keys."""
    if not url.startswith("sqlite"):
        return create_engine(url, pool_pre_ping=True)
    engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

    @event.listens_for(engine, "connect")
    def _sqlite_pragmas(dbapi_connection: Any, _record: object) -> None:  # noqa: ANN401
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA busy_timeout=30000")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.close()

    return engine


def make_session_factory(engine: Engine) -> sessionmaker[Session]:
    """Return the session factory (objects stay usable after commit)."""
    return sessionmaker(engine, expire_on_commit=False)


def migrate(engine: Engine) -> None:
    """Bring the schema to the newest migration (Alembic ``upgrade head``)."""
    config = Config()
    config.set_main_option("script_location", str(_MIGRATIONS))
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.upgrade(config, "head")
