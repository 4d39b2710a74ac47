"""The viewer as HTML: one fragment for the report and the page, one file to send.

:func:`viewer_fragment` returns the markup of one viewer (its root element, its stylesheet,
its scene as inert JSON and two inline scripts: three.js and ``viewer.js``) and the
``'sha256-...'`` sources a Content-Security-Policy must allow for those scripts.
:func:`export_viewer_html` wraps it into ``viewer.html``: a standalone page whose policy is
``default-src 'none'`` plus those two hashes, so it cannot make a request to anyone, even if
a name in it tried to (names are text, inserted with ``textContent``).
"""

from __future__ import annotations

import base64
import hashlib
import html
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from exporters.cad.jsondoc import finite_json
from exporters.errors import ExportError
from exporters.options import ExportOptions
from exporters.viewer.scene import viewer_scene
from exporters.viewer.vendor import three_script
from loceval.evaluation import EvaluationResult

__all__ = [
    "DEFAULT_TEMPLATES_DIR",
    "ViewerFragment",
    "export_viewer_html",
    "scene_fragment",
    "viewer_fragment",
    "viewer_page",
]

DEFAULT_TEMPLATES_DIR: Final[Path] = Path(__file__).resolve().parents[2] / "templates"
"""The project's templates folder (``viewer/`` and ``vendor/three/`` live there)."""
_SCRIPT: Final = Path("viewer") / "viewer.js"
_STYLE: Final = Path("viewer") / "viewer.css"
_PAGE_STYLE: Final = (
    "html,body{margin:0;background:#f3f5f8}"
    "body{min-height:100vh;display:flex;flex-direction:column;font:14px/1.4 system-ui,sans-serif;"
    "color:#1d2430}"
    "header{padding:8px 12px}header h1{font-size:16px;margin:0}header p{margin:2px 0 0;"
    "color:#4a5565;font-size:12px}.loceval-viewer{flex:1 1 auto;margin:0 12px 12px}"
)


@dataclass(frozen=True, slots=True)
class ViewerFragment:
    """One viewer's markup and what a page's Content-Security-Policy must allow for it.

    Attributes:
        html: the root element, stylesheet, scene JSON and scripts (trusted markup).
        script_sources: the ``'sha256-...'`` CSP sources of its two inline scripts.
    """

    html: str
    script_sources: tuple[str, ...]

    @property
    def csp_script_src(self) -> str:
        """Return the ``script-src`` directive's value."""
        return " ".join(self.script_sources)


def _read(templates_dir: Path, name: Path) -> str:
    path = templates_dir / name
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        msg = (
            f"The viewer's {name} cannot be read from {str(templates_dir)!r} ({err.strerror}); "
            "point templates_dir at the project's templates folder."
        )
        raise ExportError(msg) from err


def _csp_hash(script: str) -> str:
    digest = hashlib.sha256(script.encode("utf-8")).digest()
    return f"'sha256-{base64.b64encode(digest).decode('ascii')}'"


def _inline(script: str) -> str:
    """Make a script safe inside ``<script>``: no ``</script`` or ``<!--`` can end it early."""
    return script.replace("</script", "<\\/script").replace("<!--", "<\\!--")


def viewer_fragment(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    element_id: str = "loceval-viewer",
    templates_dir: Path | None = None,
) -> ViewerFragment:
    """Return the markup of one interactive viewer of an evaluation.

    Args:
        result: the evaluation.
        options: units, site, building model and title (as for the CAD files).
        element_id: the id of the root element (its scene's is ``{element_id}-scene``).
        templates_dir: the templates folder (the project's by default).

    Raises:
        ExportError: the viewer's scripts or the vendored three.js are missing or damaged.
        ExportOptionsError: bad units or site, or an unreadable building file.
    """
    folder = templates_dir or options.templates_dir or DEFAULT_TEMPLATES_DIR
    return scene_fragment(viewer_scene(result, options), folder, element_id=element_id)


def scene_fragment(
    scene: Mapping[str, object], templates_dir: Path, *, element_id: str = "loceval-viewer"
) -> ViewerFragment:
    """Return the markup of a viewer of ``scene`` (a trajectory or control-point scene).

    Raises:
        ExportError: the viewer's scripts or the vendored three.js are missing or damaged.
    """
    three = _inline(three_script(templates_dir))
    script = _inline(_read(templates_dir, _SCRIPT))
    style = _read(templates_dir, _STYLE)
    # "<" as \u003c: the JSON cannot close its <script> element, and JSON.parse reads it back
    text = finite_json(scene, indent=None, what="The viewer's scene").replace("<", "\\u003c")
    root = html.escape(element_id, quote=True)
    markup = (
        f"<style>{style}</style>\n"
        f'<div class="loceval-viewer" id="{root}" data-scene="{root}-scene" data-ready="false" '
        f'data-time-s="" data-errors="{{}}" role="group" aria-label="Interactive view of the '
        f'paths"></div>\n'
        f'<script type="application/json" id="{root}-scene">{text}</script>\n'
        f"<script>{three}</script>\n<script>{script}</script>\n"
    )
    return ViewerFragment(markup, (_csp_hash(three), _csp_hash(script)))


def viewer_page(fragment: ViewerFragment, *, title: str, subtitle: str) -> bytes:
    """Return a standalone page around one viewer: nothing but its own scripts may run.

    Its Content-Security-Policy allows its two scripts (by hash) and inline styles and
    nothing else: no request leaves the file, with or without a network.
    """
    page = (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        '<meta http-equiv="Content-Security-Policy" content="default-src \'none\'; '
        f"script-src {fragment.csp_script_src}; style-src 'unsafe-inline'; img-src data:\">\n"
        f"<title>{html.escape(title)}</title>\n<style>{_PAGE_STYLE}</style>\n</head>\n<body>\n"
        f"<header><h1>{html.escape(title)}</h1><p>{html.escape(subtitle)}</p></header>\n"
        f"{fragment.html}</body>\n</html>\n"
    )
    return page.encode("utf-8")


def export_viewer_html(result: EvaluationResult, options: ExportOptions) -> bytes:
    """Return ``viewer.html``: the viewer alone, code and data inlined, for opening from disk.

    Raises:
        ExportError: the viewer's scripts or the vendored three.js are missing or damaged.
        ExportOptionsError: bad units or site, or an unreadable building file.
    """
    reference = result.reference
    subtitle = (
        f"{len(result.estimates)} estimate(s) against {reference.name or 'the reference'} · "
        f"frame {reference.frame_id or 'reference frame'} · coordinates in {options.units} · "
        f"drag to pan or turn, wheel to zoom, click a point for its figures"
    )
    return viewer_page(viewer_fragment(result, options), title=options.title, subtitle=subtitle)
