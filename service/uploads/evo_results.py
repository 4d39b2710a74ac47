"""An uploaded evo result zip (``evo_ape``/``evo_rpe --save_results``) as a dataset.

A team's archive of evo results is uploaded like a recording; the dataset's kind is
``evo_result`` and its inspection holds the result's title, names, the seven statistics
and how many errors the zip keeps, so the archive can be listed beside new evaluations.
The zip is read once at upload (:func:`loceval.readers.evo_result.read_result_zip`), so a
broken one is refused with the reader's message.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from loceval.errors import InputError, ReaderError
from loceval.readers.evo_result import ResultZip, is_result_zip, read_result_zip
from service.db import Dataset
from service.errors import NotFoundError, is_storage_full

if TYPE_CHECKING:
    from service.runtime import Runtime
    from service.schemas.schedules import EvoResultRef

__all__ = [
    "EVO_RESULT_KIND",
    "check_evo_results",
    "inspect_result_zip",
    "is_evo_result",
    "read_evo_dataset",
]

EVO_RESULT_KIND = "evo_result"


def inspect_result_zip(path: Path, filename: str) -> dict[str, Any] | None:
    """Return the inspection of an evo result zip, or None when the zip is not one.

    Raises:
        ReaderError: the zip has evo's two JSON files but cannot be read as a result.
    """
    if not is_result_zip(path):
        return None
    try:
        result = read_result_zip(path)
    except InputError as err:
        raise ReaderError(str(err).replace(str(path), filename)) from err
    errors = result.arrays.get("error_array")
    return {
        "kind": EVO_RESULT_KIND,
        "format": "loceval" if result.loceval else "evo",
        "sources": [],
        "warnings": [],
        "result": {
            "title": str(result.info.get("title", "")),
            "ref_name": str(result.info.get("ref_name", "")),
            "est_name": str(result.info.get("est_name", "")),
            "label": str(result.info.get("label", "")),
            "stats": result.stats,
            "n": None if errors is None else int(errors.size),
            "series": "error_array" in result.arrays and "timestamps" in result.arrays,
        },
    }


def is_evo_result(dataset: Dataset) -> bool:
    """Return whether a dataset is an uploaded evo result zip."""
    return dataset.inspection.get("kind") == EVO_RESULT_KIND


def read_evo_dataset(runtime: Runtime, dataset: Dataset) -> ResultZip:
    """Read an uploaded evo result zip from the store.

    Raises:
        ReaderError: the stored zip cannot be read; the message names the dataset, never
            the server's path.
    """
    try:
        path = runtime.store.local_path(
            dataset.storage_path, filename=dataset.filename, sha256=dataset.sha256
        )
    except OSError as err:
        if is_storage_full(err):  # the cache has no room: 507, not a broken upload
            raise
        msg = (
            f"The evo result {dataset.name!r} cannot be read from the store ({err.strerror}); "
            "upload it again."
        )
        raise ReaderError(msg) from None
    try:
        return read_result_zip(path)
    except InputError as err:
        detail = str(err).replace(str(path), repr(dataset.name))
        msg = f"The evo result {dataset.name!r} cannot be read: {detail}"
        raise ReaderError(msg) from None


def check_evo_results(runtime: Runtime, project_id: str, refs: Sequence[EvoResultRef]) -> None:
    """Check that each named dataset is an evo result zip of the project.

    Raises:
        NotFoundError: a named dataset is missing (or another project's): a 404, as for
            the datasets of ``POST /evaluations``.
        InputError: a named dataset is not an evo result zip (a 422 problem).
        Both messages name ``selection.evo_results[k].dataset_id`` and what to name instead.
    """
    with runtime.sessions() as session:
        for k, ref in enumerate(refs):
            field = f"selection.evo_results[{k}].dataset_id"
            dataset = session.get(Dataset, ref.dataset_id) if "\x00" not in ref.dataset_id else None
            if dataset is None or dataset.project_id != project_id:
                msg = (
                    f"{field}: no dataset {ref.dataset_id!r} in this project; upload the evo "
                    "result zip (POST /datasets) and name the id it answers."
                )
                raise NotFoundError(msg)
            if not is_evo_result(dataset):
                kind = dataset.inspection.get("format") or dataset.inspection.get("kind")
                msg = (
                    f"{field}: the dataset {dataset.name!r} is a {kind} upload, not an evo "
                    "result zip; name a zip evo_ape or evo_rpe wrote with --save_results (its "
                    "inspection's kind is evo_result)."
                )
                raise InputError(msg)
