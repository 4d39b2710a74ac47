"""``loceval upload FILE... --server URL``: resumable uploads into a loceval service (tus 1.0).

The official Python client of the protocol, tuspy, sends each file in parts to the service's
``/api/v1/uploads``, each with its checksum; a part the connection drops is sent again from
the offset the server holds (a few tries, then the command stops with a one-line error).
Each upload's address is kept in ``uploads.json`` in the user's cache folder (tuspy's URL
storage) under the file's fingerprint (its size and first 64 KiB), the server and the key's
project, so running the same command again continues an interrupted upload instead of
starting over. A finished upload is a dataset, printed as ``id  name  kind`` (with
``--json``: the dataset documents).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Final

from loceval.errors import InputError
from service.cli.output import emit
from service.cli.remote import Server, refused, server_from_args
from service.errors import ServiceUnavailableError

if TYPE_CHECKING:
    import argparse

    from tusclient.uploader.uploader import Uploader

__all__ = ["CHUNK_MIB", "UploadOptions", "cache_dir", "chunk_bytes", "run_upload", "upload_file"]

CHUNK_MIB: Final = 16
"""The default size of one part (a cut connection sends at most this much again)."""
_RETRIES: Final = 4
_RETRY_DELAY_S: Final = 1
_DATASET_HEADER: Final = "loceval-dataset"


def cache_dir() -> Path:
    """Return the user's cache folder of loceval (``$XDG_CACHE_HOME/loceval`` and the like)."""
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "loceval"


@dataclass(frozen=True)
class UploadOptions:
    """What ``loceval upload`` and ``loceval submit`` ask of each upload."""

    tags: str = ""
    chunk_bytes: int = CHUNK_MIB << 20
    progress: bool = True


def run_upload(args: argparse.Namespace) -> int:
    """Upload each file resumably; print each dataset (id, name, kind)."""
    paths = [Path(p) for p in args.files]
    for path in paths:
        if not path.is_file():
            msg = f"{str(path)!r} is not a file; upload files (zip a bag folder first)."
            raise InputError(msg)
    options = UploadOptions(
        tags=args.tags or "",
        chunk_bytes=chunk_bytes(args.chunk_mib),
        progress=not args.quiet,
    )
    documents = []
    with server_from_args(args.server) as server:
        server.json("GET", "/datasets", params={"limit": 1})  # the server and the key, first
        for path in paths:
            dataset = upload_file(server, path, options)
            documents.append(dataset)
            if not args.json:
                emit(dataset_line(dataset))
    if args.json:
        import json  # noqa: PLC0415

        emit(json.dumps(documents, indent=2))
    return 0


def dataset_line(dataset: dict[str, Any]) -> str:
    """Return the one line that names a dataset: ``id  name  kind``."""
    return f"{dataset.get('id')}  {dataset.get('name')}  {dataset.get('kind')}"


def chunk_bytes(mib: float) -> int:
    """Return the bytes of one upload part of ``--chunk-mib`` (refused out of bounds)."""
    if not 0 < mib <= 1024:
        msg = f"--chunk-mib takes a part size from 0 to 1024 MiB, got {mib:g}."
        raise InputError(msg)
    return max(1, int(mib * (1 << 20)))


def upload_file(server: Server, path: Path, options: UploadOptions) -> dict[str, Any]:
    """Upload one file through the service's tus endpoint; return its dataset document.

    An upload of the same file to the same server and project that an earlier run left
    unfinished continues from the server's offset; one the server no longer knows (expired,
    removed) starts over.

    Raises:
        ServiceUnavailableError: the server cannot be reached, or the connection kept
            breaking (run the command again to continue).
        AuthenticationError: the key is refused.
        InputError: the server refuses the file (too large, a bad tag), with its reason.
    """
    from tusclient.client import TusClient  # noqa: PLC0415  (loaded on use)
    from tusclient.exceptions import TusCommunicationError, TusUploadFailed  # noqa: PLC0415
    from tusclient.storage.filestorage import FileStorage  # noqa: PLC0415

    folder = cache_dir()
    folder.mkdir(parents=True, exist_ok=True)
    storage = FileStorage(str(folder / "uploads.json"))
    fingerprinter = _ServerFingerprint(server)
    try:
        client = TusClient(server.uploads_url, headers={"Authorization": f"Bearer {server.key}"})
        metadata = {"filename": path.name}
        if options.tags:
            metadata["tags"] = options.tags

        def uploader() -> Uploader:
            return client.uploader(
                file_path=str(path),
                chunk_size=options.chunk_bytes,
                metadata=metadata,
                retries=_RETRIES,
                retry_delay=_RETRY_DELAY_S,
                store_url=True,
                url_storage=storage,
                fingerprinter=fingerprinter,
                upload_checksum=True,  # each part's SHA-1: a damaged part is refused (460)
            )

        try:
            try:
                up = uploader()
            except TusCommunicationError as err:
                if err.status_code not in {404, 410}:
                    raise
                # the stored upload is gone (expired, removed): start over
                storage.remove_item(fingerprinter.key_of(path))
                up = uploader()
            _send(up, path, progress=options.progress)
            last: Any = getattr(up, "request", None)  # the last PATCH (None: nothing sent)
            headers: dict[str, str] = dict(last.response_headers) if last is not None else {}
        except (TusCommunicationError, TusUploadFailed) as err:
            _raise_tus(err, server, path)
        dataset_id = headers.get(_DATASET_HEADER)
        status = server.json("GET", str(up.url))
        dataset = status.get("dataset")
        if dataset is None and dataset_id:
            dataset = server.json("GET", f"/datasets/{dataset_id}")
        if not isinstance(dataset, dict):
            msg = f"The service received {path.name} whole but made no dataset of it."
            raise ServiceUnavailableError(msg)
        storage.remove_item(fingerprinter.key_of(path))
        return dataset
    finally:
        storage.close()


def _send(up: Uploader, path: Path, *, progress: bool) -> None:
    """Send the parts from the server's offset, with a progress bar on stderr."""
    from tqdm import tqdm  # noqa: PLC0415

    size = up.get_file_size()
    with tqdm(
        total=size,
        initial=up.offset,
        unit="B",
        unit_scale=True,
        unit_divisor=1024,
        desc=path.name,
        disable=not progress,
        file=sys.stderr,
        leave=True,
    ) as bar:
        if not up.url:
            up.set_url(up.create_url())
            up.offset = 0
        while up.offset < size:
            before = up.offset
            up.stop_at = size
            up.upload_chunk()
            bar.update(up.offset - before)


def _raise_tus(err: Exception, server: Server, path: Path) -> None:
    """Turn tuspy's errors into the CLI's one-line errors."""
    status = getattr(err, "status_code", None)
    body = getattr(err, "response_content", None) or b""
    if isinstance(status, int):
        refused(status, body if isinstance(body, bytes) else str(body).encode(), server.url)
    msg = (
        f"The upload of {path.name} to {server.url} broke off ({_cause(err)}); run the same "
        "command again to continue where it stopped."
    )
    raise ServiceUnavailableError(msg) from None


def _cause(err: BaseException) -> str:
    """Return the innermost reason of a tuspy error in a few words."""
    inner: BaseException = err
    while True:
        nested = [a for a in inner.args if isinstance(a, BaseException)]
        if not nested:
            break
        inner = nested[-1]
    text = str(inner).strip() or type(inner).__name__
    return text if len(text) <= 160 else text[:157] + "..."


class _ServerFingerprint:
    """tuspy's file fingerprint, keyed also by the server's endpoint and the key's project."""

    def __init__(self, server: Server) -> None:
        from tusclient.fingerprint.fingerprint import Fingerprint  # noqa: PLC0415

        self._file = Fingerprint()
        self._prefix = f"{server.uploads_url} {server.key_id} "

    def get_fingerprint(self, fs: IO[bytes]) -> str:
        """Return the storage key of a file stream (tuspy calls this)."""
        return self._prefix + str(self._file.get_fingerprint(fs))

    def key_of(self, path: Path) -> str:
        """Return the storage key of a file."""
        with path.open("rb") as stream:
            return self.get_fingerprint(stream)
