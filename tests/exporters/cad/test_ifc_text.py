"""paths.ifc's ATE runs written as STEP text: the same entities as ifcopenshell makes them.

``IfcBuilder(text_runs=False)`` creates every run with ifcopenshell (the slow path);
the default clones each bin's first run as text (``exporters.cad.ifc_text``). Both files
are read back with ifcopenshell and compared entity for entity, with names that STEP must
escape (quotes, ``#12``, braces, accents) and with a CRS (coordinates mapped back to the
evaluation frame).
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from exporters.cad.placement import parse_site, place_evaluation
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult, evaluate

pytest.importorskip("ifcopenshell")
import ifcopenshell  # after the importorskip of its library
import ifcopenshell.validate

from exporters.cad import ifc

pytestmark = pytest.mark.filterwarnings(
    r"ignore:Exception ignored in. <_io.FileIO name='.*ifcopenshell"
    ":pytest.PytestUnraisableExceptionWarning"
)

SITE = "512340.0 5403210.5 112.3 37.5"


def _written(result: EvaluationResult, options: ExportOptions, *, text_runs: bool) -> str:
    placement = place_evaluation(result, options)
    builder = ifc.IfcBuilder(placement, ifc.georeference(options), text_runs=text_runs)
    return builder.finish(builder.build().to_string())


def _annotations(model: ifcopenshell.file) -> list[tuple[object, ...]]:
    """Every annotation with its items in order: type, coordinates and colour of each."""
    out = []
    for annotation in model.by_type("IfcAnnotation"):
        (representation,) = annotation.Representation.Representations
        items = []
        for item in representation.Items:
            (styled,) = item.StyledByItem
            (style,) = styled.Styles
            colour = style.CurveColour
            points = item.Points.CoordList if item.is_a("IfcIndexedPolyCurve") else None
            styling = (styled.Name, style.Name, style.ModelOrDraughting)
            rgb = (colour.Name, colour.Red, colour.Green, colour.Blue)
            items.append((item.is_a(), points, *styling, *rgb))
        out.append((annotation.GlobalId, annotation.Name, annotation.ObjectType, items))
    return out


def _renamed(result: EvaluationResult, names: list[str]) -> EvaluationResult:
    estimates = [
        e.estimate.__class__(
            e.estimate.stamps_ns, e.estimate.positions_xyz, e.estimate.quat_xyzw, name=name
        )
        for e, name in zip(result.estimates, names, strict=True)
    ]
    return evaluate(result.reference, estimates, result.config)


@pytest.mark.parametrize("crs", [None, "EPSG:25832"])
def test_text_runs_are_the_entities_ifcopenshell_makes(
    two_estimates: EvaluationResult, crs: str | None
) -> None:
    """Same entities by type, same annotations, same runs in the same order, valid."""
    result = _renamed(two_estimates, ["it's #12 {0}", "Ézé '#3' }{"])
    options = ExportOptions(site=parse_site(SITE), crs=crs, evaluation_id="ev-7")
    fast = ifcopenshell.file.from_string(_written(result, options, text_runs=True))
    slow = ifcopenshell.file.from_string(_written(result, options, text_runs=False))
    assert Counter(e.is_a() for e in fast) == Counter(e.is_a() for e in slow)
    assert _annotations(fast) == _annotations(slow)
    ate = [a for a in fast.by_type("IfcAnnotation") if a.ObjectType == ifc.ATE_TYPE]
    assert [a.Name for a in ate] == ["it's #12 {0} ATE", "Ézé '#3' }{ ATE"]
    for annotation in ate:
        (representation,) = annotation.Representation.Representations
        runs = representation.Items
        assert len(runs) > 10
        assert len({item.StyledByItem[0].Name for item in runs}) > 1  # several bins
    logger = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(fast, logger)
    assert logger.statements == []


def test_the_runs_follow_the_placement(two_estimates: EvaluationResult) -> None:
    """Each ATE curve, text or not, holds its run's vertices (6 decimals) in run order."""
    options = ExportOptions(site=parse_site(SITE), evaluation_id="ev-7")
    placement = place_evaluation(two_estimates, options)
    model = ifcopenshell.file.from_string(_written(two_estimates, options, text_runs=True))
    by_name = {a.Name: a for a in model.by_type("IfcAnnotation")}
    for path in placement.paths[1:]:
        (representation,) = by_name[f"{path.name} ATE"].Representation.Representations
        runs = placement.ate_runs(path)
        assert len(representation.Items) == len(runs)
        for item, run in zip(representation.Items, runs, strict=True):
            np.testing.assert_allclose(np.array(item.Points.CoordList), run.vertices, atol=5e-7)


def test_names_with_percent_signs_are_written_as_they_are(
    two_estimates: EvaluationResult,
) -> None:
    """Names holding ``%`` and ``%s`` (the text runs are filled by one %-format): as slow."""
    result = _renamed(two_estimates, ["100 % {1}", "50%s %(x)s %%"])
    options = ExportOptions(site=parse_site(SITE), evaluation_id="ev-7")
    fast = ifcopenshell.file.from_string(_written(result, options, text_runs=True))
    slow = ifcopenshell.file.from_string(_written(result, options, text_runs=False))
    assert _annotations(fast) == _annotations(slow)
    names = {item[2] for annotation in _annotations(fast) for item in annotation[3]}
    assert any(name.startswith("50%s %(x)s %% ATE") for name in names)
