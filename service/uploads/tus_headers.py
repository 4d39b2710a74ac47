"""The tus 1.0 headers: the version, the extensions, and each request header parsed and checked.

Pure parsing (no database, no store): :mod:`service.uploads.tus` acts on what these return.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import re
from typing import Final

from service.errors import TusVersionError, UploadError

__all__ = [
    "CHECKSUM_ALGORITHMS",
    "EXTENSIONS",
    "METADATA_KEYS",
    "OFFSET_MEDIA_TYPE",
    "TUS_VERSION",
    "check_version",
    "parse_checksum",
    "parse_int",
    "parse_metadata",
]

TUS_VERSION: Final = "1.0.0"
EXTENSIONS: Final = ("creation", "creation-with-upload", "termination", "checksum", "expiration")
CHECKSUM_ALGORITHMS: Final = ("sha1", "sha256", "md5")
OFFSET_MEDIA_TYPE: Final = "application/offset+octet-stream"
METADATA_KEYS: Final = frozenset({"filename", "name", "tags"})
_IGNORED_KEYS: Final = frozenset({"filetype"})  # what tus-js-client and Uppy send by habit
_MAX_METADATA: Final = 8 * 1024
_KEY: Final = re.compile(r"[A-Za-z0-9!#$%&'*+.^_`|~-]+")


def check_version(value: str | None) -> None:
    """Refuse a request without ``Tus-Resumable: 1.0.0``.

    Raises:
        TusVersionError: missing or another version (412).
    """
    if value is None or value.strip() != TUS_VERSION:
        got = "no Tus-Resumable header" if value is None else f"Tus-Resumable {value!r}"
        msg = (
            f"This server speaks tus {TUS_VERSION}, and the request has {got}; send "
            f"'Tus-Resumable: {TUS_VERSION}' (every tus client does)."
        )
        raise TusVersionError(msg)


def parse_metadata(header: str | None) -> dict[str, str]:
    """Return ``Upload-Metadata``'s pairs (``key base64value``, comma-separated), decoded.

    Raises:
        UploadError: malformed, not UTF-8, a key twice, or a key this server does not read.
    """
    found: dict[str, str] = {}
    if header is None or not header.strip():
        return found
    if len(header) > _MAX_METADATA:
        msg = f"Upload-Metadata is longer than {_MAX_METADATA} characters; send less."
        raise UploadError(msg)
    for pair in header.split(","):
        key, _, value = pair.strip().partition(" ")
        if not _KEY.fullmatch(key) or " " in value.strip():
            msg = (
                "Upload-Metadata is malformed; send comma-separated 'key base64value' pairs "
                "(keys filename, name and tags)."
            )
            raise UploadError(msg)
        if key in found:
            msg = f"Upload-Metadata names {key!r} twice; send it once."
            raise UploadError(msg)
        try:
            found[key] = base64.b64decode(value.strip(), validate=True).decode("utf-8")
        except (binascii.Error, UnicodeDecodeError):
            msg = f"Upload-Metadata's {key!r} is not base64 of UTF-8 text; encode it so."
            raise UploadError(msg) from None
    unknown = sorted(set(found) - METADATA_KEYS - _IGNORED_KEYS)
    if unknown:
        msg = (
            f"Upload-Metadata holds {', '.join(repr(k) for k in unknown)}, which this server "
            "does not read; send only filename, name and tags (comma-separated)."
        )
        raise UploadError(msg)
    return found


def parse_int(value: str | None, header: str) -> int:
    """Return a header's non-negative integer.

    Raises:
        UploadError: missing or not a non-negative integer.
    """
    if value is None or not value.strip().isdigit() or len(value.strip()) > 19:
        got = "it is missing" if value is None else f"not {value!r}"
        msg = f"{header} must be a non-negative integer (bytes), {got}."
        raise UploadError(msg)
    return int(value.strip())


def parse_checksum(value: str | None) -> tuple[str, bytes] | None:
    """Return ``Upload-Checksum``'s algorithm and digest, or None when it is not sent.

    Raises:
        UploadError: malformed, or an algorithm this server does not support (400).
    """
    if value is None:
        return None
    algorithm, _, encoded = value.strip().partition(" ")
    if algorithm.lower() not in CHECKSUM_ALGORITHMS:
        msg = (
            f"Upload-Checksum's algorithm {algorithm!r} is not supported; use one of "
            f"{', '.join(CHECKSUM_ALGORITHMS)}."
        )
        raise UploadError(msg)
    try:
        digest = base64.b64decode(encoded.strip(), validate=True)
    except binascii.Error:
        digest = b""
    if len(digest) != hashlib.new(algorithm.lower(), usedforsecurity=False).digest_size:
        msg = "Upload-Checksum must be 'ALGORITHM BASE64DIGEST' (the digest of this body)."
        raise UploadError(msg)
    return algorithm.lower(), digest
