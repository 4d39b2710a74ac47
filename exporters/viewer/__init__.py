"""The interactive 3D and plan viewer: ``viewer.html`` and the viewer of the report and page.

:mod:`~exporters.viewer.scene` builds the document it draws (in the CAD files' site frame
and units), :mod:`~exporters.viewer.reduce` the display set of long paths,
:mod:`~exporters.viewer.vendor` the pinned three.js, and :mod:`~exporters.viewer.page` the
HTML; the browser code is ``templates/viewer/viewer.js``.
"""

from __future__ import annotations

from exporters.viewer.page import ViewerFragment, export_viewer_html, viewer_fragment
from exporters.viewer.reduce import DISPLAY_BUDGET, display_indices
from exporters.viewer.scene import viewer_scene

__all__ = [
    "DISPLAY_BUDGET",
    "ViewerFragment",
    "display_indices",
    "export_viewer_html",
    "viewer_fragment",
    "viewer_scene",
]
