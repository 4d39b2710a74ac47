"""Server paths out of messages: the one scrubbing function of both front doors.

:func:`scrub` is what :func:`service.errors.problem_for` (every HTTP problem, every failed
job) and the command line's error printer pass each message through. It removes the private
folders it is given (a runtime's data directory: :attr:`service.runtime.Runtime.private_roots`,
which its blob store names; no list of them is kept in the process, so two runtimes in one
process keep their own), the per-id folders inside them, and loceval's own temporary folders
(a zipped bag's extraction folder ``/tmp/loceval-zip-.../``); the HTTP side also removes every
other folder under the temporary directory. File names stay, so a message still says which
file.

Pure Python and cheap to import: the command line loads it only to print an error.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from typing import Final

__all__ = ["scrub"]

_ID_FOLDER: Final = re.compile(
    r"(?:datasets|evaluations|runs)/[0-9a-f-]{36}/(?:\.staging-[0-9a-f]+/|artifacts/)?"
)
_NAME_CHAR: Final = r"""[^/\s'"`,;:()\[\]<>]"""
"""A character of a folder's name in a message (quotes, brackets and separators end it)."""


def _private_prefixes(roots: Iterable[Path | str]) -> list[str]:
    """Return each root as the messages may spell it (resolved and absolute), longest first."""
    prefixes = {form for root in roots for form in (Path(root).resolve(), Path(root).absolute())}
    return sorted((f"{prefix}/" for prefix in prefixes), key=len, reverse=True)


@lru_cache(maxsize=1)
def _temp_patterns() -> tuple[re.Pattern[str], re.Pattern[str]]:
    """Return (loceval's temporary folders, any folder) under the temporary directory."""
    roots = {tempfile.gettempdir(), str(Path(tempfile.gettempdir()).resolve()), "/tmp"}  # noqa: S108
    prefix = "|".join(re.escape(r.rstrip("/")) for r in sorted(roots, key=len, reverse=True))
    ours = re.compile(rf"(?:{prefix})/loceval-{_NAME_CHAR}*/?")
    folders = re.compile(rf"(?:{prefix})/(?:{_NAME_CHAR}+/)*")
    return ours, folders


def scrub(message: str, *, private: Iterable[Path | str] = (), all_temp: bool = False) -> str:
    """Remove the server's private folders from a message, keeping file names.

    Args:
        message: the message as raised.
        private: the server's folders no message may show (a runtime's data directory).
        all_temp: also remove every other folder under the temporary directory (the HTTP
            service: none of its paths there are the client's); the command line keeps
            them, as they may be the user's own files.

    Returns:
        The message without the data directory, its per-id folders and loceval's
        temporary folders.
    """
    for prefix in _private_prefixes(private):
        message = message.replace(prefix, "")
    ours, folders = _temp_patterns()
    message = ours.sub("", message)
    if all_temp:
        message = folders.sub("", message)
    return _ID_FOLDER.sub("", message)
