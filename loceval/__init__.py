"""loceval: how well does this localization system work in our building?

The numeric core: read trajectories, associate them in time, align them in space and
measure the errors. ``evaluate`` is the one pipeline the command line and the service run.
"""

from __future__ import annotations

import logging

__version__ = "0.1.0"

# Re-exported below __version__: loceval.evaluation reads it while this package loads.
from loceval.alignment import AlignMethod, AlignWindow
from loceval.association import AssociationMethod
from loceval.errors import (
    AlignmentError,
    AssociationError,
    InputError,
    LocevalError,
    MetricError,
    ReaderError,
    TrajectoryError,
)
from loceval.evaluation import (
    EvaluationConfig,
    EvaluationResult,
    Tolerance,
    evaluate,
)
from loceval.metrics import RPEUnit
from loceval.readers import read_trajectory
from loceval.trajectory import Trajectory

__all__ = [
    "AlignMethod",
    "AlignWindow",
    "AlignmentError",
    "AssociationError",
    "AssociationMethod",
    "EvaluationConfig",
    "EvaluationResult",
    "InputError",
    "LocevalError",
    "MetricError",
    "RPEUnit",
    "ReaderError",
    "Tolerance",
    "Trajectory",
    "TrajectoryError",
    "__version__",
    "evaluate",
    "read_trajectory",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())
