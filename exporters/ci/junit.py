"""``junit.xml``: the evaluation's checks as a JUnit XML test report.

One ``<testsuite>`` per estimate, or per system of trials (``--system``: its trials'
checks, prefixed with the trial's name, and one ``<error>`` case per failed trial, so a
failed trial is counted, never dropped), one ``<testcase>`` per check:

- ``tolerance``: the tolerance verdict. ``fail`` is a ``<failure>``; ``pass`` passes;
  ``undecided`` (the share's interval straddles the requirement) is a ``<failure>`` when the
  gate's conditions (``--fail-on``) include ``undecided``, and otherwise ``<skipped>`` with
  the verdict as its message: the run could not tell, which a CI system should show without
  failing the build. Without a tolerance the case is ``<skipped>`` ("no tolerance").
- one case per comparison with the baseline (when one is given; ATE and RPE RMSE, a
  system's over its trials): ``worse`` is a ``<failure>``, ``better`` and
  ``within noise`` pass, ``undetermined`` (no interval) is ``<skipped>``. A trial's own
  comparison with the baseline's trial of its name is in its system's ``<system-out>``,
  not a case: a system is judged over all its trials, as the gate judges it.

A failure's ``message`` holds the figures and the interval that decided it
("ORB-SLAM3: FAIL: 87.2 % within 0.1 m (95 % interval 85.0–89.1 %, 95 % required); ATE RMSE
0.123 m (0.110–0.135)"); its text holds the verdict's sentences. Each suite's
``<properties>`` hold the headline figures, its ``<system-out>`` the warnings. The file
validates against the Jenkins xUnit plugin's ``junit-10.xsd``, the schema Jenkins checks
reports against (GitLab and the others read the same format). ``time`` is 0: these are
measurements, not timed tests.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from typing import Final

from exporters.options import ExportOptions
from exporters.report.results import ResultsView, build_results_view
from exporters.report.trials import BaselineRow
from exporters.report.verdicts import VerdictView
from loceval.core.display import display_text
from loceval.evaluation import EvaluationResult

__all__ = ["export_junit_xml", "junit_document"]

_NOT_XML: Final = re.compile("[\ufffe\uffff]")
"""What XML 1.0 cannot hold besides the controls :func:`display_text` already replaces."""


def _text(value: str, *, one_line: bool = True) -> str:
    return _NOT_XML.sub("\ufffd", display_text(value, one_line=one_line))


@dataclass(frozen=True, slots=True)
class _Case:
    """One check: its name, and a failure or skip with its message and text (or a pass)."""

    name: str
    outcome: str  # "passed", "failure", "error" or "skipped"
    kind: str = ""
    message: str = ""
    text: str = ""


def _tolerance_case(
    view: ResultsView, k: int, verdict: VerdictView, fail_on: tuple[str, ...]
) -> _Case:
    if verdict.status == "none":
        return _Case(
            "tolerance",
            "skipped",
            "no tolerance",
            f"{verdict.name}: no tolerance to judge it against; give one to make this a check.",
        )
    name = f"tolerance {view.tolerance}" if view.tolerance else "tolerance"
    message = (
        f"{verdict.name}: {verdict.badge}: {verdict.figures}; ATE RMSE {view.figure(1, 'RMSE', k)}"
    )
    text = "\n".join((verdict.headline, *verdict.details))
    if verdict.status == "pass":
        return _Case(name, "passed", text=text)
    if verdict.status == "fail" or "undecided" in fail_on:
        return _Case(name, "failure", verdict.status, message, text)
    return _Case(name, "skipped", verdict.status, message, text)


def _baseline_words(row: BaselineRow) -> str:
    """``ATE RMSE 0.349 m against 0.017 m: +0.332 m (paired 95 % interval 0.327–0.337 m)``."""
    interval = "" if row.interval == "—" else f" ({row.how} 95 % interval {row.interval})"
    return f"{row.metric} {row.now} against {row.baseline}: {row.difference}{interval}"


def _baseline_rows(view: ResultsView, name: str, *, judged: bool) -> list[BaselineRow]:
    """The baseline rows of estimate or system ``name`` that are (or are not) checks."""
    rows = () if view.baseline is None else view.baseline.rows
    return [r for r in rows if r.name == name and ((r.name, r.metric) in view.judged) == judged]


def _baseline_case(row: BaselineRow) -> _Case:
    what = " (over the trials)" if row.name.endswith(" (system)") else ""
    name = f"baseline {row.metric}{what}"
    words = _baseline_words(row)
    message = f"{row.name}: {row.verdict}: {words}"
    if row.status == "worse":
        return _Case(name, "failure", "worse", message, words)
    if row.status == "undetermined":
        return _Case(name, "skipped", "undetermined", message, words)
    return _Case(name, "passed", text=f"{row.verdict}: {words}")


def _cases_of_estimate(
    view: ResultsView, k: int, fail_on: tuple[str, ...], *, trial: bool = False
) -> list[_Case]:
    """The tolerance case of estimate ``k`` and its baseline cases (named by it in a system)."""
    name = view.estimate_names[k]
    cases = [_tolerance_case(view, k, view.verdicts[k], fail_on)]
    cases += [_baseline_case(row) for row in _baseline_rows(view, name, judged=True)]
    if trial:  # a system's suite holds its trials' cases: each says which trial
        cases = [replace(c, name=f"{c.name}: {name}") for c in cases]
    return cases


def _testsuite(
    name: str,
    k: int,
    view: ResultsView,
    *,
    cases: list[_Case],
    properties: list[tuple[str, str]],
    notes: list[str],
) -> ET.Element:
    suite = ET.Element(
        "testsuite",
        {
            "name": _text(name),
            "tests": str(len(cases)),
            "failures": str(sum(c.outcome == "failure" for c in cases)),
            "errors": str(sum(c.outcome == "error" for c in cases)),
            "skipped": str(sum(c.outcome == "skipped" for c in cases)),
            "time": "0",
            "timestamp": view.created_at,
            "id": str(k),
            "package": "loceval",
        },
    )
    listed = ET.SubElement(suite, "properties")
    for key, value in [("evaluation_id", view.evaluation_id), *properties]:
        ET.SubElement(listed, "property", {"name": _text(key), "value": _text(value)})
    for case in cases:
        element = ET.SubElement(
            suite,
            "testcase",
            {"name": _text(case.name), "classname": _text(f"loceval.{name}"), "time": "0"},
        )
        if case.outcome != "passed":
            detail = ET.SubElement(
                element, case.outcome, {"type": _text(case.kind), "message": _text(case.message)}
            )
            detail.text = _text(case.text, one_line=False)
        elif case.text:
            ET.SubElement(element, "system-out").text = _text(case.text, one_line=False)
    if notes:
        ET.SubElement(suite, "system-out").text = _text("\n".join(notes), one_line=False)
    return suite


def _estimate_properties(view: ResultsView, k: int) -> list[tuple[str, str]]:
    found = [
        ("ate_rmse", view.figure(1, "RMSE", k)),
        ("rpe_rmse", view.figure(2, "RMSE", k)),
        *((f"share {label}", values[k]) for label, values in view.shares),
    ]
    if view.verdicts[k].status != "none":
        found.append(("verdict", view.verdicts[k].status))
    return found


def _warnings_of(view: ResultsView, names: set[str]) -> list[str]:
    return [f"warning ({about}): {text}" for about, text in view.warnings if about in names]


def _estimate_suite(view: ResultsView, k: int, fail_on: tuple[str, ...]) -> ET.Element:
    name = view.estimate_names[k]
    cases = _cases_of_estimate(view, k, fail_on)
    notes = _warnings_of(view, {name})
    return _testsuite(
        name, k, view, cases=cases, properties=_estimate_properties(view, k), notes=notes
    )


def _system_suite(
    view: ResultsView, number: int, system: str, fail_on: tuple[str, ...]
) -> ET.Element:
    trials = [k for k, s in enumerate(view.estimate_systems) if s == system]
    found = view.trials
    failed = [] if found is None else [f for f in found.failed if f.system == system]
    cases = [c for k in trials for c in _cases_of_estimate(view, k, fail_on, trial=True)]
    cases += [
        _Case(f"trial {f.name}", "error", "failed trial", f"{f.name}: {f.reason}", f.reason)
        for f in failed
    ]
    cases += [
        _baseline_case(row) for row in _baseline_rows(view, f"{system} (system)", judged=True)
    ]
    rows = [] if found is None else [r for r in found.rows if r.system == system]
    properties = [("trials", str(len(trials))), ("failed_trials", str(len(failed)))]
    properties += [
        (
            row.metric,
            f"median {row.median}, mean {row.mean} ± {row.std}, 95 % interval {row.interval}",
        )
        for row in rows
    ]
    names = {system, *(view.estimate_names[k] for k in trials)}
    notes = _warnings_of(view, names)
    # each trial against the baseline's trial of its name: shown, not a check
    notes += [
        f"baseline, trial {row.name}: {row.verdict}: {_baseline_words(row)}"
        for k in trials
        for row in _baseline_rows(view, view.estimate_names[k], judged=False)
    ]
    return _testsuite(system, number, view, cases=cases, properties=properties, notes=notes)


def _systems(view: ResultsView) -> list[str]:
    """The systems of trials, in order (each once)."""
    if view.trials is None:
        return []
    return list(dict.fromkeys(row.system for row in view.trials.rows))


def junit_document(view: ResultsView, *, fail_on: tuple[str, ...] = ()) -> ET.Element:
    """Return the ``<testsuites>`` element of an evaluation's view model.

    Args:
        view: the report's figure-free view model.
        fail_on: the gate's conditions (``undecided`` makes an undecided verdict a failure).
    """
    suites = [
        _estimate_suite(view, k, fail_on)
        for k in range(len(view.estimate_names))
        if not (view.estimate_systems and view.estimate_systems[k])
    ]
    first = len(view.estimate_names)
    suites += [
        _system_suite(view, first + n, system, fail_on) for n, system in enumerate(_systems(view))
    ]
    root = ET.Element(
        "testsuites",
        {
            "name": _text(f"loceval: {view.title}"),
            "tests": str(sum(int(s.get("tests", "0")) for s in suites)),
            "failures": str(sum(int(s.get("failures", "0")) for s in suites)),
            "errors": str(sum(int(s.get("errors", "0")) for s in suites)),
            "time": "0",
        },
    )
    root.extend(suites)
    return root


def export_junit_xml(result: EvaluationResult, options: ExportOptions) -> bytes:
    """Return ``junit.xml``: a test suite per estimate, a test case per check.

    Args:
        result: the evaluation.
        options: the title, the evaluation id and the gate's conditions (``fail_on``).
    """
    root = junit_document(build_results_view(result, options), fail_on=options.fail_on)
    ET.indent(root)
    data: bytes = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    return data + b"\n"
