"""What CI systems read: ``junit.xml`` (test reports) and ``summary.md`` (job summaries).

Both render the report's figure-free view model
(:func:`exporters.report.results.build_results_view`): the same verdicts, tables, intervals and
comparisons as ``report.html``, so no figure is computed or formatted twice.

- :func:`~exporters.ci.junit.export_junit_xml`: a test suite per estimate, a test case per
  check (the tolerance verdict; each comparison with the baseline), the figures and the
  interval in a failure's message. Jenkins, GitLab, GitHub (through a JUnit action),
  Azure Pipelines and Buildkite all show it.
- :func:`~exporters.ci.markdown.export_summary_md`: the results table, the verdicts, the
  comparisons and the gate in GitHub-flavoured Markdown, for ``$GITHUB_STEP_SUMMARY`` and
  merge-request comments.
"""

from __future__ import annotations

from exporters.ci.junit import export_junit_xml
from exporters.ci.markdown import export_summary_md

__all__ = ["export_junit_xml", "export_summary_md"]
