"""The HTTP side of ``loceval upload`` and ``loceval submit``: a loceval service's API by httpx.

Each failure reaches the user as one line (the CLI's :class:`~loceval.errors.LocevalError`
path, exit 1): a server that cannot be reached (:class:`ServiceUnavailableError`), a key it
refuses (401/403, :class:`AuthenticationError`), and anything else it refuses (4xx) with the
``detail`` of its problem document (:class:`InputError`, the option's name included).
The key comes from ``LOCEVAL_API_KEY`` and travels as ``Authorization: Bearer KEY``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NoReturn, Self
from urllib.parse import urlsplit

import httpx2 as httpx

from loceval.errors import InputError
from service.errors import AuthenticationError, ServiceUnavailableError

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "API_KEY_VARIABLE",
    "Server",
    "file_sha256",
    "server_from_args",
]

API_KEY_VARIABLE: Final = "LOCEVAL_API_KEY"
"""The environment variable that holds the key of the project to upload into."""

_TIMEOUT: Final = httpx.Timeout(60.0, connect=10.0)
_HASH_BLOCK: Final = 1 << 20


def server_from_args(url: str) -> Server:
    """Return the service at ``url`` with the key from ``LOCEVAL_API_KEY``.

    Raises:
        InputError: the URL is not an http(s) address, or the variable is not set.
    """
    parts = urlsplit(url.strip())
    if parts.scheme not in {"http", "https"} or not parts.netloc:
        msg = f"--server takes the service's address like http://host:8000, got {url!r}."
        raise InputError(msg)
    key = os.environ.get(API_KEY_VARIABLE, "").strip()
    if not key:
        msg = (
            f"Set {API_KEY_VARIABLE} to your project's API key (`loceval keys create "
            "--project NAME` on the server makes one)."
        )
        raise InputError(msg)
    return Server(url.strip().rstrip("/"), key)


def file_sha256(path: Path) -> str:
    """Return the SHA-256 (hex) of a file, read in blocks."""
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        while block := stream.read(_HASH_BLOCK):
            digest.update(block)
    return digest.hexdigest()


class Server:
    """A loceval service: its address, the project's key, and one HTTP connection pool."""

    def __init__(self, url: str, key: str) -> None:
        """Keep the address (no trailing slash) and the key; open the connection pool."""
        self.url = url
        self.key = key
        self.client = httpx.Client(base_url=f"{url}/api/v1", headers=self.headers, timeout=_TIMEOUT)

    @property
    def headers(self) -> dict[str, str]:
        """The headers of every request: the key, and JSON answers."""
        return {"Authorization": f"Bearer {self.key}", "Accept": "application/json"}

    @property
    def uploads_url(self) -> str:
        """The tus endpoint where uploads are created."""
        return f"{self.url}/api/v1/uploads"

    @property
    def key_id(self) -> str:
        """A short one-way tag of the key: uploads stored for one project are not another's."""
        return hashlib.sha256(self.key.encode("utf-8")).hexdigest()[:16]

    def close(self) -> None:
        """Close the connections."""
        self.client.close()

    def __enter__(self) -> Self:
        """Use the server for a ``with`` block."""
        return self

    def __exit__(self, *_exc: object) -> None:
        """Close the connections at the block's end."""
        self.close()

    def request(self, method: str, path: str, **kwargs: Any) -> httpx.Response:  # noqa: ANN401
        """Send a request to the API (``path`` under ``/api/v1`` or a full URL of the server).

        Raises:
            ServiceUnavailableError: the server cannot be reached, or answers 5xx.
            AuthenticationError: the key is refused (401, 403).
            InputError: any other 4xx, with its problem document's detail.
        """
        try:
            response = self.client.request(method, path, **kwargs)
        except httpx.TransportError as err:
            self.unreachable(err)
        self.check(response)
        return response

    def json(self, method: str, path: str, **kwargs: Any) -> Any:  # noqa: ANN401
        """Send a request; return its JSON answer."""
        return self.request(method, path, **kwargs).json()

    def unreachable(self, err: BaseException) -> NoReturn:
        """Raise the one-line error of a server that cannot be reached."""
        why = str(err).strip() or type(err).__name__
        msg = f"Cannot reach the loceval service at {self.url} ({why}); check --server."
        raise ServiceUnavailableError(msg) from None

    def check(self, response: httpx.Response) -> None:
        """Raise the one-line error of a refused request; nothing for a 2xx or 3xx."""
        refused(response.status_code, response.content, self.url)

    def dataset_by_sha256(self, sha256: str) -> dict[str, Any] | None:
        """Return the project's dataset holding these bytes, or None."""
        page = self.json("GET", "/datasets", params={"sha256": sha256, "limit": 1})
        items = page.get("items") or []
        return dict(items[0]) if items else None

    def download(self, url: str, target: Path) -> None:
        """Stream an artifact into ``target`` (written whole or not at all)."""
        partial = target.with_name(target.name + ".part")
        try:
            with self.client.stream("GET", url) as response:
                if response.status_code >= 400:
                    response.read()
                    self.check(response)
                with partial.open("wb") as out:
                    for block in response.iter_bytes():
                        out.write(block)
        except httpx.TransportError as err:
            partial.unlink(missing_ok=True)
            self.unreachable(err)
        partial.replace(target)


def refused(status: int, body: bytes, server: str) -> None:
    """Raise the one-line error of an HTTP answer that refuses (4xx, 5xx); else nothing."""
    if status < 400:
        return
    detail = problem_detail(body)
    if status in {401, 403}:
        msg = (
            f"The loceval service at {server} refused the API key ({status}); set "
            f"{API_KEY_VARIABLE} to a valid key of your project."
        )
        raise AuthenticationError(msg)
    if status >= 500:
        msg = f"The loceval service at {server} failed ({status}){': ' + detail if detail else ''}."
        raise ServiceUnavailableError(msg)
    raise InputError(detail or f"The loceval service at {server} refused the request ({status}).")


def problem_detail(body: bytes) -> str:
    """Return the ``detail`` of a problem document (or its ``title``), else ``""``."""
    import json  # noqa: PLC0415

    try:
        document: Mapping[str, Any] = json.loads(body)
    except ValueError:
        return ""
    if not isinstance(document, dict):
        return ""
    detail = document.get("detail") or document.get("title") or ""
    return " ".join(str(detail).split())
