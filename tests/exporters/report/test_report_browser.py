"""The HTML report in headless Chromium: no console errors, every image decoded."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

from exporters.options import ExportOptions
from exporters.report import render_report_html
from loceval.evaluation import EvaluationResult
from tests.conftest import require_tool

# Injected at the very top of <head>, before the report's Content-Security-Policy, so it
# runs; it records errors (script errors, failed resources, CSP refusals, console.error and
# console.warn), waits for the load event, decodes every <img> and writes a JSON summary
# into the DOM for --dump-dom.
PROBE = """<script>
(function () {
  var errors = [];
  window.addEventListener("error", function (e) {
    var t = e.target;
    errors.push("error: " + (e.message || (t && (t.currentSrc || t.src || t.href)) || t));
  }, true);
  window.addEventListener("securitypolicyviolation", function (e) {
    errors.push("csp: " + e.violatedDirective + " " + e.blockedURI);
  });
  ["error", "warn"].forEach(function (level) {
    var original = console[level];
    console[level] = function () {
      errors.push("console." + level + ": " + Array.prototype.join.call(arguments, " "));
      return original.apply(console, arguments);
    };
  });
  window.addEventListener("load", function () {
    var images = Array.prototype.slice.call(document.images);
    Promise.all(images.map(function (img) {
      return img.decode().then(
        function () { return img.naturalWidth > 0 && img.naturalHeight > 0; },
        function () { return false; });
    })).then(function (decoded) {
      var out = document.createElement("pre");
      out.id = "browser-check";
      out.textContent = JSON.stringify({
        images: images.length,
        decoded: decoded.filter(Boolean).length,
        errors: errors
      });
      document.body.appendChild(out);
    });
  });
})();
</script>"""

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--hide-scrollbars",
    "--virtual-time-budget=15000",
)


def _check_in_chromium(html: str, tmp_path: Path) -> dict[str, object]:
    """Load ``html`` with the probe in headless Chromium and return the probe's summary."""
    chromium = require_tool("chromium")
    page = tmp_path / "report.html"
    page.write_text(html.replace("<head>", "<head>\n" + PROBE, 1), encoding="utf-8")
    proc = subprocess.run(
        [
            chromium,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={tmp_path / 'profile'}",
            "--dump-dom",
            page.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    match = re.search(r'<pre id="browser-check">([^<]*)</pre>', proc.stdout)
    assert match is not None, f"no probe result; chromium said: {proc.stderr[-2000:]}"
    summary: dict[str, object] = json.loads(match.group(1))
    return summary


def test_report_loads_cleanly_in_chromium(two_estimates: EvaluationResult, tmp_path: Path) -> None:
    """Chromium shows the report with no errors and decodes all seven plots."""
    html = render_report_html(two_estimates, ExportOptions(title="Browser check")).decode()
    summary = _check_in_chromium(html, tmp_path)
    assert summary["errors"] == []
    assert summary["images"] == 8  # Figs. 1-7 and the clock correlation (issue 13)
    assert summary["decoded"] == 8


def test_probe_catches_broken_and_external_images(tmp_path: Path) -> None:
    """The check itself works: a corrupt image and a blocked network image are reported."""
    html = (
        '<!DOCTYPE html><html><head><meta http-equiv="Content-Security-Policy" '
        "content=\"default-src 'none'; img-src data:\"></head><body>"
        '<img src="data:image/png;base64,AAAA"><img src="https://example.invalid/x.png">'
        "</body></html>"
    )
    summary = _check_in_chromium(html, tmp_path)
    assert summary["images"] == 2
    assert summary["decoded"] == 0
    errors = summary["errors"]
    assert isinstance(errors, list)
    assert any(str(e).startswith("csp: img-src") for e in errors)
