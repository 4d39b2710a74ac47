"""The S3 client of the object-storage backend, and what its failures become.

:func:`make_client` configures boto3 from the conventional ``AWS_*`` variables;
:func:`store_errors` turns a failing store into the 503 the service answers.
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, TypeVar

import boto3
import botocore.loaders
import botocore.session
from botocore.config import Config
from botocore.exceptions import BotoCoreError, ClientError

from service.errors import StoreUnavailableError

if TYPE_CHECKING:
    from mypy_boto3_s3 import S3Client

__all__ = ["is_missing", "load_models", "make_client", "store_errors", "unless_missing"]

T = TypeVar("T")


@contextlib.contextmanager
def store_errors() -> Iterator[None]:
    """Raise StoreUnavailableError when the object store fails (unreachable, refusing)."""
    try:
        yield
    except (BotoCoreError, ClientError) as err:
        code = err.response.get("Error", {}).get("Code", "") if isinstance(err, ClientError) else ""
        msg = (
            f"The object store cannot be used ({type(err).__name__}{' ' + code if code else ''}); "
            "try again in a minute (GET /readyz shows when it is back)."
        )
        raise StoreUnavailableError(msg) from err


def is_missing(err: ClientError) -> bool:
    """Return whether the store answered that the object or bucket does not exist."""
    return err.response.get("Error", {}).get("Code") in {"404", "NoSuchKey", "NotFound"}


def unless_missing(call: Callable[[], T]) -> T | None:
    """Return ``call()``, or None when the store answers that there is no such object.

    Raises:
        StoreUnavailableError: the store failed otherwise (see :func:`store_errors`).
    """
    with store_errors():
        try:
            return call()
        except ClientError as err:
            if is_missing(err):
                return None
            raise


def make_client(*, pool: int = 32) -> S3Client:
    """Return an S3 client configured from the conventional ``AWS_*`` variables."""
    endpoint = os.environ.get("AWS_ENDPOINT_URL") or None
    config = Config(
        max_pool_connections=pool,
        retries={"max_attempts": 5, "mode": "standard"},
        # Unsigned payloads: over plain HTTP botocore would otherwise hash every part it
        # sends (SHA-256, 1.4 s of CPU for a 2 GB upload); the upload hashes its bytes once
        # already, and HTTPS (what real deployments use) protects them on the way.
        s3={"addressing_style": "path" if endpoint else "auto", "payload_signing_enabled": False},
        # S3-compatible stores do not all know the newer default checksums
        request_checksum_calculation="when_required",
        response_checksum_validation="when_required",
        connect_timeout=10,
        read_timeout=120,
    )
    region = os.environ.get("AWS_REGION") or os.environ.get("AWS_DEFAULT_REGION") or "us-east-1"
    client: S3Client = _session().client(
        "s3", endpoint_url=endpoint, region_name=region, config=config
    )
    return client


@functools.cache
def _data_loader() -> botocore.loaders.Loader:
    """Return the process's one loader of botocore's data (the S3 model, read once)."""
    return botocore.loaders.create_loader()


def _session() -> boto3.session.Session:
    """Return a new boto3 session (it reads the ``AWS_*`` variables) with the shared loader.

    A session of its own reads botocore's S3 model anew (0.3-0.4 s of CPU); sharing the
    loader makes a client in a job process (one per job) in milliseconds.
    """
    core = botocore.session.Session()
    loader = _data_loader()
    core.register_component("data_loader", loader)
    session = boto3.session.Session(botocore_session=core)
    paths = loader.search_paths  # boto3 appends its data folder to the loader each time
    paths[:] = list(dict.fromkeys(paths))
    return session


def load_models() -> None:
    """Read botocore's S3 model now (the jobs' forkserver: every job inherits it).

    A client is made with placeholder keys (no credential lookup, no request sent).
    """
    placeholder = "-"  # the client sends nothing
    _session().client(
        "s3",
        region_name="us-east-1",
        aws_access_key_id=placeholder,
        aws_secret_access_key=placeholder,
    )
