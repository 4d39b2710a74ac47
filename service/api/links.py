"""Absolute links in responses, built from the configured public address only.

A response's ``Location`` header and its artifact ``url`` fields must point at the service
as its users reach it, whatever ``Host`` or ``X-Forwarded-Host`` header a client sent: a
link built from a request header lets anyone who can send a request hand out links to a
host of their choosing. Every absolute link therefore starts with ``LOCEVAL_PUBLIC_URL``
(a path prefix such as ``https://example.org/loceval/`` included), through :func:`api_url`.
"""

from __future__ import annotations

from urllib.parse import quote

from service.settings import Settings

__all__ = ["api_url", "public_base"]


def public_base(settings: Settings) -> str:
    """Return the public address with exactly one trailing slash.

    Args:
        settings: the service settings (``public_url``).

    Returns:
        ``https://host/prefix/`` or ``https://host/``.
    """
    return settings.resolved_public_url.rstrip("/") + "/"


def api_url(settings: Settings, *segments: str) -> str:
    """Return the public URL of an ``/api/v1`` resource.

    Args:
        settings: the service settings (``public_url``).
        segments: the path below ``/api/v1`` (``"datasets"``, a dataset id); each is
            percent-encoded, so no segment can add folders or a query.

    Returns:
        For example ``https://host/prefix/api/v1/datasets/ID``.
    """
    path = "/".join(quote(s, safe="") for s in segments)
    return f"{public_base(settings)}api/v1/{path}"
