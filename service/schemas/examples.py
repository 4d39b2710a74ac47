"""Examples of the API's answers for ``/docs``: real answers of the service, trimmed.

Without an example of its own, Swagger UI shows ``"string"`` for a text and, for a text with a
``pattern``, a random string matching it; so each answer's schema carries one of these
(:data:`BY_SCHEMA`, set by :func:`service.api.docs.document_examples`: FastAPI's own writing of
the document drops every ``null``, which a real answer holds), taken from answers the service
gave on the public TUM recordings (``fr2_desk``) and shortened where a list repeats.
``tests/service/api/test_docs_examples.py`` holds each to its schema.
"""

from __future__ import annotations

from typing import Any, Final

__all__ = [
    "ARTIFACT",
    "BY_SCHEMA",
    "COMPARISON",
    "DATASET",
    "DATASET_UPLOADED",
    "EVALUATION",
    "HOPS_ANSWER",
    "HOPS_REFUSED",
    "OPTION",
    "PROGRESS",
    "SCHEDULE",
    "SCHEDULE_RUN",
    "SCHEDULE_WITH_SECRET",
    "SOURCE",
    "SUMMARY_ROW",
]

_EVALUATION_ID: Final = "297a1e94-c86c-4e41-a598-ddbfae842cde"
_REFERENCE_ID: Final = "e427b92b-95f8-41e4-9bfd-7c6126ce58ba"
_ESTIMATE_ID: Final = "26dcd1ee-d6ab-43f3-a9d1-7de7c3c461b6"
_SCHEDULE_ID: Final = "5b0f2a7e-3c41-4d8e-9a6b-1f2e3d4c5b6a"
_RUN_ID: Final = "c7e9d1a3-6b2f-4e08-8d5c-2a4b6c8e0f13"
_BASE: Final = "https://loceval.example.org/api/v1"

PROGRESS: Final[dict[str, Any]] = {"stage": "done", "fraction": 1.0}
SOURCE: Final[dict[str, Any]] = {"dataset_id": _ESTIMATE_ID, "selector": None, "name": "ORB-SLAM2"}
SUMMARY_ROW: Final[dict[str, Any]] = {
    "name": "ORB-SLAM2",
    "ate_rmse_m": 0.0081,
    "rpe_rmse_m": 0.0034,
    "matched": 2222,
    "verdict": "pass",
}
ARTIFACT: Final[dict[str, Any]] = {
    "name": "report.pdf",
    "media_type": "application/pdf",
    "size_bytes": 412_337,
    "url": f"{_BASE}/evaluations/{_EVALUATION_ID}/artifacts/report.pdf",
    "filename": "ORB-SLAM2-report.pdf",
}

DATASET: Final[dict[str, Any]] = {
    "id": _ESTIMATE_ID,
    "name": "fr2_desk_ORB.txt",
    "filename": "fr2_desk_ORB.txt",
    "kind": "tum",
    "size_bytes": 303_374,
    "sha256": "9601009dd5124a841ce58f5d9681f28cdaadde651db02e2e9151e335f4aa5ef4",
    "tags": ["fr2", "desk"],
    "created_at": "2026-11-29T08:26:09.219220Z",
    "inspection": {
        "kind": "tum",
        "format": "tum",
        "source": "tum:fr2_desk_ORB.txt",
        "poses": 2893,
        "duration_s": 98.822,
        "length_m": 21.73,
        "rate_hz": 31.086,
        "orientation": True,
        "sources": [
            {
                "selector": None,
                "kind": "file",
                "description": "TUM trajectory",
                "pose_count": 2893,
                "first_stamp_ns": 1311868164363181056,
                "last_stamp_ns": 1311868263185529088,
                "duration_s": 98.822348,
                "rate_hz": 31.086,
                "length_m": 21.73,
                "orientation": True,
                "indexed": False,
            }
        ],
        "warnings": [],
    },
}
DATASET_UPLOADED: Final[dict[str, Any]] = {
    **DATASET,
    "upload": {"deduplicated": False, "tags_added": [], "name_kept": None, "notes": []},
}

RESUMABLE_UPLOAD: Final[dict[str, Any]] = {
    "id": "6f1c2b0e-3a5d-4c8e-9b7a-2d4e6f8a0c1b",
    "offset": 303_374,
    "length": 303_374,
    "filename": "fr2_desk_ORB.txt",
    "name": None,
    "tags": ["fr2", "desk"],
    "expires": "2026-11-30T08:26:09.219220Z",
    "dataset": DATASET,
    "upload": DATASET_UPLOADED["upload"],
    "error": None,
}
"""A resumable upload whose last byte has arrived: the dataset it became."""

EVALUATION: Final[dict[str, Any]] = {
    "id": _EVALUATION_ID,
    "status": "succeeded",
    "progress": PROGRESS,
    "attempts": 1,
    "created_at": "2026-11-29T08:26:09.598363Z",
    "started_at": "2026-11-29T08:26:09.992607Z",
    "finished_at": "2026-11-29T08:26:21.614718Z",
    "reference": {"dataset_id": _REFERENCE_ID, "selector": None, "name": None},
    "estimates": [{**SOURCE, "system": None}],
    "options": {"align": "se3", "tolerance": "0.10@95", "units": "mm"},
    "summary": [SUMMARY_ROW],
    "error": None,
    "artifacts": [
        {
            "name": "report.html",
            "media_type": "text/html",
            "size_bytes": 1_203_441,
            "url": f"{_BASE}/evaluations/{_EVALUATION_ID}/artifacts/report.html",
            "filename": "ORB-SLAM2-report.html",
        },
        ARTIFACT,
    ],
    "result": None,
}

OPTION: Final[dict[str, Any]] = {
    "key": "max_gap_s",
    "kind": "number",
    "default": 0.1,
    "help": "the longest reference gap bridged by interpolation, seconds",
    "words": "the maximum gap",
    "flag": "--max-gap",
    "metavar": "S",
    "minimum": 1e-09,
    "maximum": 1_000_000.0,
    "exclusive_minimum": False,
    "choices": [],
    "max_length": None,
    "min_length": None,
    "pattern": None,
    "example": None,
    "group": "evaluation",
    "auto": False,
    "bounds": "at least 1e-09 and at most 1e+06",
    "bounds_hint": "more than 0",
    "label": "Max gap (s)",
}

SCHEDULE: Final[dict[str, Any]] = {
    "id": _SCHEDULE_ID,
    "name": "Weekly level 2",
    "cron": "0 7 * * mon",
    "timezone": "Europe/Berlin",
    "paused": False,
    "selection": {"tags": ["level-2"], "name_pattern": None, "uploaded_within_days": 7.0},
    "template": {
        "reference": {"selector": "/gt"},
        "estimates": [{"selector": "/amcl_pose", "name": "AMCL"}],
        "options": {"tolerance": "0.10@95"},
    },
    "produce": {"summary_formats": ["summary.html", "summary.pdf"], "per_run_artifacts": False},
    "webhook_url": "https://hooks.example.org/loceval",
    "next_fire_at": "2026-11-30T06:00:00Z",
    "last_fired_at": "2026-11-23T06:00:00Z",
    "created_at": "2026-11-02T09:14:03.512000Z",
    "updated_at": "2026-11-02T09:14:03.512000Z",
}
SCHEDULE_WITH_SECRET: Final[dict[str, Any]] = {
    **SCHEDULE,
    "webhook_secret": "3c8f0b6d2a9e41f7b5d0c2e8a6f4b1d9e7c5a3f1b8d6e4c2a0f9b7d5c3e1a8f6",
}
SCHEDULE_RUN: Final[dict[str, Any]] = {
    "id": _RUN_ID,
    "schedule_id": _SCHEDULE_ID,
    "trigger": "cron",
    "due_at": "2026-11-23T06:00:00Z",
    "status": "succeeded",
    "progress": PROGRESS,
    "note": None,
    "rows": [
        {
            "dataset": "level2-2026-11-20.mcap",
            "status": "succeeded",
            "error": None,
            "evaluation_id": _EVALUATION_ID,
            "summary": [SUMMARY_ROW],
        }
    ],
    "error": None,
    "artifacts": [
        {
            "name": "summary.pdf",
            "media_type": "application/pdf",
            "size_bytes": 98_304,
            "url": f"{_BASE}/schedules/{_SCHEDULE_ID}/runs/{_RUN_ID}/artifacts/summary.pdf",
            "filename": "run-2026-11-23-c7e9d1a3-summary.pdf",
        }
    ],
    "webhook": {"status": "delivered", "attempts": 1, "http_status": 200},
    "attempts": 1,
    "created_at": "2026-11-23T06:00:01.204000Z",
    "started_at": "2026-11-23T06:00:01.731000Z",
    "finished_at": "2026-11-23T06:02:44.118000Z",
}

COMPARISON: Final[dict[str, Any]] = {
    "metric": "ate_rmse",
    "items": [
        {
            "label": "ORB-SLAM2",
            "source": "loceval",
            "evaluation_id": _EVALUATION_ID,
            "dataset_id": None,
            "title": "ATE RMSE of ORB-SLAM2 on fr2_desk",
            "stats": {"rmse": 0.0081, "mean": 0.0072, "median": 0.0069, "max": 0.0246},
            "n": 2222,
            "ci95": {"rmse": [0.0077, 0.0086]},
            "intervals": "bootstrap over blocks of poses",
        },
        {
            "label": "rgbdslam",
            "source": "evo",
            "evaluation_id": None,
            "dataset_id": "a1f0c3e5-7b9d-4f21-8c3e-5d7f9a1b3c5e",
            "title": "APE w.r.t. translation part (m)",
            "stats": {"rmse": 0.0135, "mean": 0.0121, "median": 0.0114, "max": 0.0352},
            "n": 2222,
            "ci95": None,
            "intervals": "none (an evo result carries no intervals)",
        },
    ],
    "comparisons": [
        {
            "a": "ORB-SLAM2",
            "b": "rgbdslam",
            "difference": -0.0054,
            "ci95": [-0.0061, -0.0047],
            "verdict": "a_better",
            "n_common": 2222,
            "summary": "ORB-SLAM2 is better by 5.4 mm (95 % interval 4.7 to 6.1 mm).",
            "unavailable": None,
        }
    ],
    "notes": [],
}

HOPS_ANSWER: Final[dict[str, Any]] = {
    "pointer": "/hops/paths",
    "values": [
        {
            "ParamName": "Names",
            "InnerTree": {"{0}": [{"type": "System.String", "data": '"ORB-SLAM2"'}]},
        }
    ],
    "errors": [],
    "warnings": [],
}
HOPS_REFUSED: Final[dict[str, Any]] = {
    "values": [],
    "errors": ["The Evaluation input is empty; connect a panel with the evaluation's id."],
    "warnings": [],
}

BY_SCHEMA: Final[dict[str, dict[str, Any]]] = {
    "ArtifactPublic": ARTIFACT,
    "ComparisonPublic": COMPARISON,
    "DatasetPublic": DATASET,
    "DatasetUploaded": DATASET_UPLOADED,
    "EstimateRef": {**SOURCE, "system": None},
    "EvaluationPublic": EVALUATION,
    "HopsAnswer": HOPS_ANSWER,
    "OptionPublic": OPTION,
    "ProgressPublic": PROGRESS,
    "ResumableUploadPublic": RESUMABLE_UPLOAD,
    "SchedulePublic": SCHEDULE,
    "ScheduleRunPublic": SCHEDULE_RUN,
    "ScheduleWithSecret": SCHEDULE_WITH_SECRET,
    "SourceRef": SOURCE,
    "SummaryRow": SUMMARY_ROW,
}
"""The example of each answer's schema (components/schemas), by the schema's name."""
