"""``loceval storage migrate``: move a data folder's uploads and artifacts into a bucket."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from loceval.errors import InputError

if TYPE_CHECKING:
    import argparse

__all__ = ["run_storage_migrate"]


def run_storage_migrate(args: argparse.Namespace) -> int:
    """Copy the folder's datasets and artifacts into LOCEVAL_BLOB_URL's bucket."""
    from service.blobs.migrate import migrate_folder  # noqa: PLC0415
    from service.cli.serve import _open_runtime, _settings  # noqa: PLC0415
    from service.jobs.queue import create_runtime  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    settings = _settings(get_settings)
    if not settings.blob_url:
        msg = (
            "Set LOCEVAL_BLOB_URL=s3://BUCKET[/PREFIX] (and AWS_ENDPOINT_URL, AWS_ACCESS_KEY_ID, "
            "AWS_SECRET_ACCESS_KEY) to the bucket to move the data folder into."
        )
        raise InputError(msg)
    source = Path(args.source) if args.source else settings.data_dir
    if not (source / "datasets").is_dir():
        msg = f"{str(source)!r} is not a loceval data folder (it has no datasets/); pass --from."
        raise InputError(msg)
    runtime = _open_runtime(create_runtime, settings)
    try:
        counts = migrate_folder(runtime, source, say=print)
    except ValueError as err:
        raise InputError(str(err)) from None
    finally:
        runtime.close()
    print(  # noqa: T201
        f"Moved {counts.datasets} datasets and {counts.artifacts} artifact files "
        f"({counts.bytes / 1e6:,.1f} MB) into {settings.blob_url}; {counts.already} datasets "
        f"were there already. The folder {str(source)!r} is unchanged: delete its datasets/, "
        "evaluations/ and runs/ once the service runs from the bucket."
    )
    for dataset_id, path in counts.missing or []:
        print(f"warning: dataset {dataset_id}: {path} is missing; it was left as it is")  # noqa: T201
    return 1 if counts.missing else 0
