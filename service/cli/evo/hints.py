"""What an evo flag given to ``loceval evaluate`` is called there (issues 28 and 30).

evo's users type ``evo_ape tum gt.txt est.txt -as`` from memory; ``loceval evaluate`` does
not take evo's flags (``loceval ape`` and ``loceval rpe`` do), so an unknown argument that
is one of evo's gets a message naming the loceval option that does the same. This module is
pure Python: the parser imports it without numpy.
"""

from __future__ import annotations

from typing import Final

__all__ = ["EVALUATE_EPILOG", "EVO_EQUIVALENTS", "evo_hint"]

EVALUATE_EPILOG: Final = (
    "evo's command lines (evo_ape tum gt.txt est.txt -as) run as `loceval ape` and "
    "`loceval rpe`, with evo's flags and defaults; `loceval res` reads evo's result zips."
)

EVO_EQUIVALENTS: Final[dict[str, str]] = {
    "-a": "--align se3 (loceval evaluate's default)",
    "--align": "--align se3 (loceval evaluate's default)",
    "-s": "--align sim3",
    "--correct_scale": "--align sim3",
    "-as": "--align sim3",
    "-sa": "--align sim3",
    "--n_to_align": "--align-first N",
    "--align_origin": "--align origin",
    "-r": "nothing: it prints translation (m) and rotation (deg) errors both",
    "--pose_relation": "nothing: it prints translation (m) and rotation (deg) errors both",
    "--t_max_diff": "--associate nearest --max-dt S",
    "--t_offset": "--time-offset S",
    "--delta": "--rpe-delta D",
    "--delta_unit": "--rpe-unit frames|m|s",
    "--all_pairs": "--rpe-all-pairs",
    "-p": "--out DIR (writes report.html)",
    "--plot": "--out DIR (writes report.html)",
    "--save_plot": "--out DIR (writes report.html and report.pdf)",
    "--save_results": "--out DIR (writes result.json and errors.csv)",
    "--plot_mode": "--out DIR (the report has plan and side views)",
    "--t_start": "nothing yet (loceval ape takes it)",
    "--t_end": "nothing yet (loceval ape takes it)",
    "-v": "nothing: it always prints its notes",
    "--verbose": "nothing: it always prints its notes",
    "--silent": "--json (prints only the result document)",
}
"""evo's flag -> what ``loceval evaluate`` calls the same thing."""


def evo_hint(flag: str) -> str | None:
    """Return what ``loceval evaluate`` calls evo's ``flag``, or None for a flag evo lacks.

    The one-line message of an unknown argument (:func:`service.cli.usage.unknown_arguments`)
    says it in place of the nearest option: ``-as`` is no typo of ``--align``.
    """
    if flag not in EVO_EQUIVALENTS:
        return None
    return (
        f"evo's {flag} is {EVO_EQUIVALENTS[flag]} in loceval evaluate, or keep evo's "
        "command line: loceval ape tum GT EST -as (and loceval rpe)"
    )
