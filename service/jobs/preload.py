"""Imported once by the jobs' forkserver: what every job's process starts with.

:mod:`service.jobs.limits` runs each job in a process forked from a server process that imported
this module, so a job does not import NumPy, SciPy, Matplotlib, Typst and the CAD
libraries anew (seconds per job), nor compile the report templates. A module that fails to
import is left out here (the job that needs it reports the failure itself); the server must
start whatever is missing.
"""

from __future__ import annotations

import contextlib
import importlib
from typing import Final

__all__ = ["MODULES"]

MODULES: Final = (
    "service.jobs.runner",
    "loceval.evaluation",
    "loceval.readers",
    "loceval.checkpoint_evaluation",
    "loceval.assessment.assess",
    "exporters",
    "exporters.cad.placement",
    "exporters.tables",
    "exporters.report",
    "exporters.plots",
    "exporters.plots.figure",
    "exporters.plots.maps",
    "exporters.plots.series",
    "exporters.plots.render",
    "exporters.plots.mpl",  # matplotlib: the trials', ranging and map plots
    "exporters.report.render",
    "exporters.report.typeset",
    "jinja2",
    "typst",
    "exporters.cad.dxf",
    "exporters.cad.rhino",
    "exporters.cad.gltf",
    "exporters.cad.ifc",
    "exporters.checkpoints",
    "loceval.readers.rosbag",
    "service.blobs.ranged",  # a bag in a bucket, read where it lies (boto3)
)
"""The modules a job's process needs, loaded once in the forkserver."""


def _preload() -> None:
    for name in MODULES:
        with contextlib.suppress(Exception):  # a missing optional library: its job says so
            importlib.import_module(name)
    with contextlib.suppress(Exception):  # boto3 missing: no bucket to read from
        importlib.import_module("service.blobs.s3client").load_models()
    with contextlib.suppress(Exception):  # Jinja2 missing: the report job says so itself
        render = importlib.import_module("exporters.report.render")
        render.preload_templates()  # the repository's templates, compiled once for every job
    with contextlib.suppress(Exception):  # typst missing: the report job says so itself
        # the fonts Typst sets the PDFs in, read once (matplotlib's DejaVu)
        importlib.import_module("exporters.report.typeset").preload_fonts()


_preload()
