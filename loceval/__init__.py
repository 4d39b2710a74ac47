"""loceval: how well does this localization system work in our building?

The numeric core: read trajectories, associate them in time, align them in space and
measure the errors. ``evaluate`` is the one pipeline the command line and the service run.
"""

from __future__ import annotations

import importlib
import logging
from typing import TYPE_CHECKING, Final

from loceval._version import __version__

if TYPE_CHECKING:  # the names as the type checker sees them; at run time see __getattr__
    from loceval.errors import (
        AlignmentError,
        AssociationError,
        InputError,
        LocevalError,
        MetricError,
        ReaderError,
        TrajectoryError,
    )
    from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
    from loceval.metrics.pose_errors import RPEUnit
    from loceval.readers import read_trajectory
    from loceval.registration.alignment import AlignMethod, AlignWindow
    from loceval.registration.association import AssociationMethod
    from loceval.trajectory import Trajectory

_LAZY: Final = {
    "AlignMethod": "loceval.registration.alignment",
    "AlignWindow": "loceval.registration.alignment",
    "AssociationMethod": "loceval.registration.association",
    "AlignmentError": "loceval.errors",
    "AssociationError": "loceval.errors",
    "InputError": "loceval.errors",
    "LocevalError": "loceval.errors",
    "MetricError": "loceval.errors",
    "ReaderError": "loceval.errors",
    "TrajectoryError": "loceval.errors",
    "EvaluationConfig": "loceval.evaluation",
    "EvaluationResult": "loceval.evaluation",
    "Tolerance": "loceval.evaluation",
    "evaluate": "loceval.evaluation",
    "RPEUnit": "loceval.metrics.pose_errors",
    "read_trajectory": "loceval.readers",
    "Trajectory": "loceval.trajectory",
}
"""Public name -> the module defining it, imported on first use so `import loceval` is cheap
(the command line's help and the errors module need none of the numeric modules)."""

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


def __getattr__(name: str) -> object:
    """Import a public name's module on first use (PEP 562) and cache the name here."""
    module = _LAZY.get(name)
    if module is None:
        msg = f"module {__name__!r} has no attribute {name!r}"
        raise AttributeError(msg)
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """List the public names, loaded or not."""
    return sorted({*globals(), *__all__})
