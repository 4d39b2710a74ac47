"""Logging of the service, configured once at start-up: one line per request and per job step.

:func:`configure_logging` puts one handler on the root logger: JSON lines when stderr is not
a terminal (a container, a service manager), readable lines on a terminal. Every line
carries the context of where it was written (:func:`log_context`: ``request_id`` in a
request, ``job_id``, ``kind`` and ``project`` in a job), and the fields a call passes with
``extra={...}``. uvicorn's loggers are routed through the same handler; its access log is
off (``serve`` passes ``access_log=False``) because
:class:`service.api.requestlog.RequestLogMiddleware` writes one line per request with the
request id.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import sys
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from typing import IO, Any, Final

__all__ = [
    "JsonFormatter",
    "TextFormatter",
    "configure_logging",
    "current_context",
    "log_context",
    "log_transition",
    "reset_logging",
]

_CONTEXT: ContextVar[Mapping[str, str]] = ContextVar("loceval_log_context", default={})  # noqa: B039  (never mutated)
_UVICORN: Final = ("uvicorn", "uvicorn.error", "uvicorn.access")
_QUIET: Final = {"huey": logging.WARNING, "huey.consumer": logging.WARNING}
_RECORD_FIELDS: Final = frozenset(
    logging.LogRecord("", 0, "", 0, "", (), None).__dict__.keys() | {"message", "asctime"}
)


def current_context() -> Mapping[str, str]:
    """Return the log context of this thread or task."""
    return _CONTEXT.get()


@contextmanager
def log_context(**values: str | None) -> Iterator[None]:
    """Add ``values`` (``None`` ones left out) to every log line written inside the block."""
    merged = {**_CONTEXT.get(), **{k: v for k, v in values.items() if v is not None}}
    token = _CONTEXT.set(merged)
    try:
        yield
    finally:
        _CONTEXT.reset(token)


def _fields(record: logging.LogRecord) -> dict[str, Any]:
    """Return the context and the ``extra`` fields of a record."""
    fields: dict[str, Any] = dict(getattr(record, "context", None) or {})
    fields.update(
        (key, value)
        for key, value in record.__dict__.items()
        if key not in _RECORD_FIELDS and key != "context"
    )
    return fields


class _ContextFilter(logging.Filter):
    """Copy the log context onto each record (it is read in the writing thread)."""

    def filter(self, record: logging.LogRecord) -> bool:
        """Attach the context; keep every record."""
        record.context = dict(_CONTEXT.get())
        return True


class JsonFormatter(logging.Formatter):
    """One JSON object per line: time, level, logger, message, context and extra fields."""

    def format(self, record: logging.LogRecord) -> str:
        """Return the record as one line of JSON."""
        line: dict[str, Any] = {
            "time": dt.datetime.fromtimestamp(record.created, dt.UTC).isoformat(
                timespec="milliseconds"
            ),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
            **_fields(record),
        }
        if record.exc_info:
            line["exception"] = self.formatException(record.exc_info)
        return json.dumps(line, default=str)


class TextFormatter(logging.Formatter):
    """A readable line for a terminal: time, level, message, then ``key=value`` fields."""

    def format(self, record: logging.LogRecord) -> str:
        """Return the record as one readable line (and its traceback, if any)."""
        stamp = time.strftime("%H:%M:%S", time.localtime(record.created))
        fields = " ".join(f"{k}={v}" for k, v in _fields(record).items())
        text = f"{stamp} {record.levelname:<7} {record.name}: {record.getMessage()}"
        text = f"{text}  {fields}" if fields else text
        if record.exc_info:
            text = f"{text}\n{self.formatException(record.exc_info)}"
        return text


class _LocevalHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """The one handler :func:`configure_logging` installs (found again by its class)."""


def configure_logging(
    *, stream: IO[str] | None = None, json_lines: bool | None = None, level: int = logging.INFO
) -> None:
    """Send every log line of the process through one handler; calling again replaces it.

    Args:
        stream: where lines go (default: stderr).
        json_lines: JSON lines, or readable ones (default: JSON unless ``stream`` is a TTY).
        level: the root logger's level.
    """
    stream = stream or sys.stderr
    if json_lines is None:
        json_lines = not (hasattr(stream, "isatty") and stream.isatty())
    root = logging.getLogger()
    for old in [h for h in root.handlers if isinstance(h, _LocevalHandler)]:
        root.removeHandler(old)
    handler = _LocevalHandler(stream)
    handler.setFormatter(JsonFormatter() if json_lines else TextFormatter())
    handler.addFilter(_ContextFilter())
    root.addHandler(handler)
    root.setLevel(level)
    for name in _UVICORN:
        uvicorn_logger = logging.getLogger(name)
        uvicorn_logger.handlers.clear()
        uvicorn_logger.propagate = True
    for name, quiet in _QUIET.items():
        logging.getLogger(name).setLevel(quiet)


def reset_logging() -> None:
    """Remove what :func:`configure_logging` installed (tests call it between tests)."""
    root = logging.getLogger()
    for old in [h for h in root.handlers if isinstance(h, _LocevalHandler)]:
        root.removeHandler(old)
    root.setLevel(logging.WARNING)
    for name in _QUIET:
        logging.getLogger(name).setLevel(logging.NOTSET)


_JOBS: Final = logging.getLogger("service.jobs")


def log_transition(
    event: str,
    kind: str,
    job_id: str,
    *,
    level: int = logging.INFO,
    **fields: Any,  # noqa: ANN401
) -> None:
    """Write the one log line of a job's transition (queued, started, succeeded, ...)."""
    _JOBS.log(
        level,
        "%s %s %s",
        kind,
        job_id,
        event,
        extra={
            "event": event,
            "kind": kind,
            "job_id": job_id,
            **{key: value for key, value in fields.items() if value is not None},
        },
    )
