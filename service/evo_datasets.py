"""An uploaded evo result zip (``evo_ape``/``evo_rpe --save_results``) as a dataset.

A team's archive of evo results is uploaded like a recording; the dataset's kind is
``evo_result`` and its inspection holds the result's title, names, the seven statistics
and how many errors the zip keeps, so the archive can be listed beside new evaluations.
The zip is read once at upload (:func:`loceval.readers.evo_result.read_result_zip`), so a
broken one is refused with the reader's message.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from loceval.errors import InputError, ReaderError
from loceval.readers.evo_result import is_result_zip, read_result_zip

__all__ = ["EVO_RESULT_KIND", "inspect_result_zip"]

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
