"""``junit.xml``: the evaluation's checks as a JUnit XML test report.

One ``<testsuite>`` per estimate, one ``<testcase>`` per check:

- ``tolerance``: the tolerance verdict. ``fail`` is a ``<failure>``; ``pass`` passes;
  ``undecided`` (the share's interval straddles the requirement) is a ``<failure>`` when the
  gate's conditions (``--fail-on``) include ``undecided``, and otherwise ``<skipped>`` with
  the verdict as its message: the run could not tell, which a CI system should show without
  failing the build. Without a tolerance the case is ``<skipped>`` ("no tolerance").
- one case per comparison with the baseline (when one is given): ``worse`` is a
  ``<failure>``, ``better`` and ``within noise`` pass.

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
from dataclasses import dataclass
from typing import Final

from exporters.options import ExportOptions
from exporters.report.verdicts import VerdictView
from exporters.report.view import ResultsView, build_results_view
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
    outcome: str  # "passed", "failure" or "skipped"
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


def _suite(view: ResultsView, k: int, fail_on: tuple[str, ...]) -> ET.Element:
    name = view.estimate_names[k]
    cases = [_tolerance_case(view, k, view.verdicts[k], fail_on)]
    suite = ET.Element(
        "testsuite",
        {
            "name": _text(name),
            "tests": str(len(cases)),
            "failures": str(sum(c.outcome == "failure" for c in cases)),
            "errors": "0",
            "skipped": str(sum(c.outcome == "skipped" for c in cases)),
            "time": "0",
            "timestamp": view.created_at,
            "id": str(k),
            "package": "loceval",
        },
    )
    properties = ET.SubElement(suite, "properties")
    figures = [
        ("evaluation_id", view.evaluation_id),
        ("ate_rmse", view.figure(1, "RMSE", k)),
        ("rpe_rmse", view.figure(2, "RMSE", k)),
        *((f"share {label}", values[k]) for label, values in view.shares),
    ]
    if view.verdicts[k].status != "none":
        figures.append(("verdict", view.verdicts[k].status))
    for key, value in figures:
        ET.SubElement(properties, "property", {"name": _text(key), "value": _text(value)})
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
    warnings = [f"warning ({about}): {text}" for about, text in view.warnings if about == name]
    if warnings:
        ET.SubElement(suite, "system-out").text = _text("\n".join(warnings), one_line=False)
    return suite


def junit_document(view: ResultsView, *, fail_on: tuple[str, ...] = ()) -> ET.Element:
    """Return the ``<testsuites>`` element of an evaluation's view model.

    Args:
        view: the report's figure-free view model.
        fail_on: the gate's conditions (``undecided`` makes an undecided verdict a failure).
    """
    suites = [_suite(view, k, fail_on) for k in range(len(view.estimate_names))]
    root = ET.Element(
        "testsuites",
        {
            "name": _text(f"loceval: {view.title}"),
            "tests": str(sum(int(s.get("tests", "0")) for s in suites)),
            "failures": str(sum(int(s.get("failures", "0")) for s in suites)),
            "errors": "0",
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
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"
