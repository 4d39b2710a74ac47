"""The report's ranging section and plots (exporters.report.ranging, exporters.plots.ranging)."""

from __future__ import annotations

import re

import numpy as np

from exporters import ExportOptions
from exporters.plots import render_plots
from exporters.report.render import render_report_html
from loceval.radio_evaluation import RangingConfig, evaluate_radio
from tests.radio_factory import make_ranges, make_reference


def test_ranging_section_and_plots(rng: np.random.Generator) -> None:
    """One table row per heard anchor plus overall; three ranging plots after the others."""
    result = evaluate_radio(make_reference(), make_ranges(rng, end_s=20.0).ranges, RangingConfig())
    assert result.ranging is not None
    keys = [p.key for p in render_plots(result)]
    assert keys[-3:] == ["ranging_distance", "ranging_time", "ranging_plan"]
    html = render_report_html(result, ExportOptions()).decode("utf-8")
    section = html[html.index('<section id="ranging"') :]
    section = section[: section.index("</section>")]
    rows = re.findall(r'<tr><th scope="row">([^<]+)</th>', section)
    assert rows == [a.id for a in result.ranging.anchors] + ["overall"]
    overall = result.ranging.overall
    assert f'<td class="num">{overall.rmse_m:.3f}</td>' in section
    assert "Never heard: " in section
    assert "solve = nlls, minmax" in section


def test_no_ranging_no_section(rng: np.random.Generator) -> None:
    """An evaluation without ranges has neither the section nor the plots."""
    result = evaluate_radio(make_reference(), make_ranges(rng, end_s=20.0).ranges, RangingConfig())
    plain = type(result)(
        reference=result.reference,
        estimates=result.estimates,
        config=result.config,
        reference_warnings=(),
        created_at=result.created_at,
    )
    assert not any(p.key.startswith("ranging") for p in render_plots(plain))
    assert 'id="ranging"' not in render_report_html(plain, ExportOptions()).decode("utf-8")
