"""The report templates' compiled code kept between processes: Jinja2's bytecode cache.

Every ``loceval`` command that writes a report is a new process, and Jinja2 compiled the
report's templates from source in each (15 templates, 0.06 s of a 1.3 s ``report.html``).
:class:`jinja2.FileSystemBytecodeCache` keeps the compiled code in a folder that only this
user can write (``$TMPDIR/_jinja2-cache-UID``, mode 0700, which Jinja2 checks), keyed by
the template's path and checked against its source, so an edited template is compiled
again. The service's job processes have the templates compiled already
(:func:`exporters.report.render.preload_templates`); the cache spares their start too.

A cache only saves time: a folder that cannot be made or written, a full disk or a damaged
entry leaves the template compiled from source, never a failed report.
"""

from __future__ import annotations

import contextlib

import jinja2
from jinja2.bccache import Bucket

__all__ = ["QuietBytecodeCache", "bytecode_cache"]


class QuietBytecodeCache(jinja2.FileSystemBytecodeCache):
    """A :class:`jinja2.FileSystemBytecodeCache` whose failures compile from source."""

    def load_bytecode(self, bucket: Bucket) -> None:
        """Load the bucket's code; a missing or damaged entry leaves the bucket empty."""
        try:
            super().load_bytecode(bucket)
        except Exception:  # noqa: BLE001  (unpickling and unmarshalling raise many kinds)
            bucket.reset()

    def dump_bytecode(self, bucket: Bucket) -> None:
        """Write the bucket's code; a folder or disk that refuses it is left alone."""
        with contextlib.suppress(OSError):
            super().dump_bytecode(bucket)


def bytecode_cache(directory: str | None = None) -> QuietBytecodeCache | None:
    """Return the cache in ``directory`` (None: Jinja2's per-user temporary folder).

    Returns:
        The cache, or None when its folder cannot be made or is not safely this user's.
    """
    try:
        return QuietBytecodeCache(directory)
    except (OSError, RuntimeError):  # RuntimeError: Jinja2 found the folder unsafe
        return None
