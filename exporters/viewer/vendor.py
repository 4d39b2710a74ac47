"""The vendored three.js: where it lives, the pinned version and hash, and its inlinable form.

three.js (MIT) is vendored, not fetched: ``templates/vendor/three/three.module.min.js`` is
the ``build/three.module.min.js`` of the npm package at :data:`THREE_VERSION`, with its
``LICENSE``. Refresh it with ``make vendor-three THREE_VERSION=x.y.z`` (``npm pack``, copy,
print the new hash), then update :data:`THREE_VERSION` and :data:`THREE_SHA256`; the test
``tests/exporters/viewer/test_viewer.py`` checks the file against them.

The module build ends in one ``export{a as WebGLRenderer,...}`` clause and imports nothing,
so :func:`three_script` turns it into a classic script (the clause becomes the object
``globalThis.LOCEVAL_THREE``): inline ``<script type="module">`` code cannot import another
inline script, and a ``blob:`` URL would be a request of sorts. The vendored file stays
byte for byte as published.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Final

from exporters.errors import ExportError

__all__ = ["THREE_FILE", "THREE_SHA256", "THREE_VERSION", "three_script"]

THREE_VERSION: Final = "0.170.0"
"""The npm version of three the vendored file comes from (tarball integrity
sha512-FQK+LEpYc0fBD+J8g6oSEyyNzjp+Q7Ks1C568WWaoMRLW+TkNNWmenWeGgJjV105Gd+p/2ql1ZcjYvNiPZBhuQ==)."""
THREE_SHA256: Final = "08fd7545d13d2c7fb65ab691530a802dafefd638596501854f267d0fb13c39e7"
"""SHA-256 of the vendored ``three.module.min.js``."""
THREE_FILE: Final = Path("vendor") / "three" / "three.module.min.js"
"""The vendored file, relative to the templates folder."""

_EXPORT_CLAUSE: Final = re.compile(r"export\s*\{([^}]*)\}\s*;?\s*$")
_EXPORT_ITEM: Final = re.compile(r"^([A-Za-z_$][\w$]*)(?:\s+as\s+([A-Za-z_$][\w$]*))?$")


def three_script(templates_dir: Path) -> str:
    """Return the vendored three.js as a classic script that sets ``globalThis.LOCEVAL_THREE``.

    Raises:
        ExportError: the file is missing, or differs from the pinned hash (a damaged or
            hand-edited copy); run ``make vendor-three`` to restore it.
    """
    path = templates_dir / THREE_FILE
    try:
        data = path.read_bytes()
    except OSError as err:
        msg = (
            f"The vendored three.js {str(path)!r} cannot be read ({err.strerror}); point "
            "templates_dir at the project's templates folder or run make vendor-three."
        )
        raise ExportError(msg) from err
    digest = hashlib.sha256(data).hexdigest()
    if digest != THREE_SHA256:
        msg = (
            f"The vendored three.js {str(path)!r} has SHA-256 {digest}, not the pinned "
            f"{THREE_SHA256} of three {THREE_VERSION}; run make vendor-three to restore it."
        )
        raise ExportError(msg)
    source = data.decode("utf-8")
    clause = _EXPORT_CLAUSE.search(source)
    if clause is None:
        msg = f"The vendored three.js {str(path)!r} does not end in an export clause."
        raise ExportError(msg)
    names = []
    for item in clause.group(1).split(","):  # one per exported name (about 700), not per pose
        found = _EXPORT_ITEM.match(item.strip())
        if found is None:
            msg = f"Unexpected export {item!r} in the vendored three.js {str(path)!r}."
            raise ExportError(msg)
        local, exported = found.group(1), found.group(2) or found.group(1)
        names.append(f"{exported}:{local}")
    body = source[: clause.start()]
    return (
        "(function(){\n"
        + body
        + "\nglobalThis.LOCEVAL_THREE=Object.freeze({"
        + ",".join(names)
        + "});\n})();\n"
    )
