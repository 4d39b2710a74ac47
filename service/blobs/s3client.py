"""The S3 client of the object-storage backend, and what its failures become.

:func:`make_client` configures boto3 from the conventional ``AWS_*`` variables;
:func:`store_errors` turns a failing store into the 503 the service answers.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, TypeVar

import boto3
from botocore.config import Config
from botocore.exceptions import BotoCoreError, ClientError

from service.errors import StoreUnavailableError

if TYPE_CHECKING:
    from mypy_boto3_s3 import S3Client

__all__ = ["is_missing", "make_client", "store_errors", "unless_missing"]

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
    client: S3Client = boto3.session.Session().client(
        "s3", endpoint_url=endpoint, region_name=region, config=config
    )
    return client
