"""Layering: dependency direction, import cycles, module length and core messages.

The core never pulls in web, templating or CAD libraries; no module of loceval, exporters or
service reaches itself through its imports; no module is longer than 600 lines; core and
exporter strings name no command-line flag. The last three read the source with ``ast``, and
each check is also run on small fake trees that hold a violation or none.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
import textwrap
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Final

import pytest

BANNED = ("fastapi", "pydantic", "ezdxf", "trimesh", "rhino3dm", "weasyprint", "typst", "jinja2",
          "matplotlib", "rosbags", "exporters", "service")  # fmt: skip


@pytest.mark.parametrize(
    ("module", "allowed"),
    [
        ("loceval", ()),
        ("loceval.evaluation", ()),
        ("loceval.readers", ()),
        ("exporters", ("exporters",)),
        ("service.cli", ("exporters", "service")),
    ],
)
def test_import_pulls_in_no_banned_module(module: str, allowed: tuple[str, ...]) -> None:
    """Importing a layer loads none of the heavy or upward modules (lazy imports only)."""
    code = (
        f"import json, sys; import {module}; "
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="."
    )
    loaded = set(json.loads(out.stdout))
    assert not (loaded & (set(BANNED) - set(allowed)))


def test_import_loceval_loads_no_numeric_module() -> None:
    """``import loceval`` is cheap: the public names load their modules on first use."""
    code = (
        "import json, sys; import loceval; before = sorted(sys.modules); "
        "names = [getattr(loceval, n) for n in loceval.__all__]; "
        "print(json.dumps([before, sorted(sys.modules)]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="."
    )
    before, after = (set(mods) for mods in json.loads(out.stdout))
    assert not {"numpy", "scipy", "loceval.evaluation", "loceval.readers"} & before
    assert {"numpy", "loceval.evaluation", "loceval.readers"} <= after


def test_evaluate_path_loads_no_scipy() -> None:
    """Reading text trajectories and evaluating them imports no scipy (its start-up cost)."""
    code = (
        "import json, sys; import loceval.evaluation, loceval.readers; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="."
    )
    assert json.loads(out.stdout) == []


# --- Import graph, module length and messages, read from the source with ast ----------

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("loceval", "exporters", "service")
CORE_PACKAGES = ("loceval", "exporters")
MAX_MODULE_LINES = 600
MAX_TOP_MODULES = 10
"""``loceval/`` keeps the value types, errors, options and the pipelines' entry points at its
top; everything else lives in the folder of its stage."""

STAGES: Final[tuple[tuple[str, ...], ...]] = (
    ("loceval.errors", "loceval.optionspec", "loceval._version"),
    ("loceval.options", "loceval.core"),
    ("loceval.trajectory", "loceval.controlpoints"),
    ("loceval.readers",),
    ("loceval.inspection", "loceval.registration"),
    ("loceval.metrics",),
    ("loceval.calibration", "loceval.assessment"),
    ("loceval.checkpoints", "loceval.radio", "loceval.maps"),
    ("loceval.evaluation",),
    ("loceval.checkpoint_evaluation", "loceval.radio_evaluation"),
    ("loceval.results",),
    ("loceval",),
    ("exporters.errors",),
    ("exporters.options",),
    ("exporters.colours", "exporters.tables", "exporters.mapcells"),
    ("exporters.cad",),
    ("exporters.plots", "exporters.viewer"),
    ("exporters.report",),
    ("exporters.summary", "exporters.checkpoints", "exporters.ci"),
    ("exporters",),
)
"""The stages of the data flow, lowest first: a module imports only modules of its own stage
folder or of a lower stage (readers never import metrics, metrics never import calibration,
the core never imports the exporters, ...). Stages on one row are siblings that import
neither each other nor anything above them."""

SERVICE_STAGES: Final[tuple[tuple[str, ...], ...]] = (
    ("service.redact",),
    ("service.errors",),
    ("service.webhooks",),
    ("service.settings", "service.logs", "service.schemas"),
    ("service.db",),
    ("service.migrations", "service.adapters"),
    ("service.auth", "service.preflight"),
    ("service.blobs",),
    ("service.runtime",),
    ("service.uploads",),
    ("service.jobs",),
    ("service.schedules", "service.results"),
    ("service.api",),
    ("service.main",),
    ("service.cli",),
    ("service",),
)
"""The service's rooms, lowest first, above the core's and the exporters' stages: what every
process shares at the top of ``service/`` (errors, settings, logging, the database, the
runtime), then the blob stores, the uploads, the jobs (the registry names the schedules'
executors as ``"module:function"`` and imports none), the schedules and finished results,
the routes, the app and the command line."""
MAX_SERVICE_TOP_MODULES = 12
"""``service/`` keeps what every process shares at its top; each concern is a folder."""

HTTP_MODULES: Final = ("fastapi", "starlette", "uvicorn", "pydantic", "httpx")
HTTP_ERROR_NAMES: Final = frozenset(
    {"HTTPException", "RequestValidationError", "WebSocketException"}
)
_FLAG = re.compile(r"(?<![-!\w])--[A-Za-z]")
"""A command-line flag: ``--`` then a letter, not inside ``---`` or an XML ``<!--``."""


def module_files(root: Path, packages: Sequence[str]) -> dict[str, Path]:
    """Map every module of ``packages`` under ``root`` to its file (packages to __init__.py)."""
    modules: dict[str, Path] = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def imported_modules(path: Path, module: str, known: Collection[str]) -> set[str]:
    """Return the modules of ``known`` that ``module`` imports anywhere in its source.

    Every ``import`` and ``from ... import`` counts, at module level or inside functions,
    classes, ``try`` or ``if TYPE_CHECKING`` blocks. Relative imports are resolved against
    the module's package; ``from pkg import name`` is an import of ``pkg.name`` when that is
    a module, else of ``pkg``; ``import a.b.c`` is an import of the longest known prefix.
    """
    is_package = path.name == "__init__.py"
    package = module if is_package else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(_known_prefix(alias.name, known) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.add(candidate if candidate in known else _known_prefix(base, known))
    found.discard("")
    found.discard(module)  # `from . import x` inside x's own package is no self-import
    return found


def _known_prefix(name: str, known: Collection[str]) -> str:
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        prefix = ".".join(parts[:end])
        if prefix in known:
            return prefix
    return ""


def import_cycles(root: Path, packages: Sequence[str]) -> list[list[str]]:
    """Return one cycle (a closed path of modules) per group of modules that import each other."""
    files = module_files(root, packages)
    graph = {name: sorted(imported_modules(path, name, files)) for name, path in files.items()}
    reach = {name: _reachable(graph, name) for name in graph}
    groups = {
        frozenset({name} | {other for other in reach[name] if name in reach[other]})
        for name in graph
        if name in reach[name]
    }
    return sorted(_cycle_within(graph, set(group)) for group in groups)


def _reachable(graph: Mapping[str, Sequence[str]], start: str) -> set[str]:
    """Return the modules reachable from ``start`` by one or more imports."""
    seen: set[str] = set()
    todo = list(graph[start])
    while todo:
        node = todo.pop()
        if node not in seen:
            seen.add(node)
            todo.extend(graph[node])
    return seen


def _cycle_within(graph: Mapping[str, Sequence[str]], group: set[str]) -> list[str]:
    """Return a shortest closed path through the group's first module (breadth first)."""
    start = min(group)
    parent: dict[str, str] = {}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for nxt in graph[node]:
            if nxt == start:
                path = [node]
                while path[-1] != start:
                    path.append(parent[path[-1]])
                return [start, *reversed(path[:-1]), start] if node != start else [start, start]
            if nxt in group and nxt not in parent:
                parent[nxt] = node
                queue.append(nxt)
    return sorted(group)  # unreachable for a strongly connected group


def long_modules(root: Path, packages: Sequence[str], limit: int) -> dict[str, int]:
    """Return the modules longer than ``limit`` lines, with their line counts."""
    counts = {
        name: len(path.read_text(encoding="utf-8").splitlines())
        for name, path in module_files(root, packages).items()
    }
    return {name: n for name, n in counts.items() if n > limit}


def flag_strings(root: Path, packages: Sequence[str]) -> list[str]:
    """Return ``module:line: text`` for every string literal (not a docstring) naming a flag."""
    hits: list[str] = []
    for name, path in module_files(root, packages).items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        # A string standing alone as a statement is a docstring (of a module, class,
        # function or attribute), never a message.
        docstrings = {
            id(node.value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        }
        hits.extend(
            f"{name}:{node.lineno}: {node.value!r}"
            for node in ast.walk(tree)
            if isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docstrings
            and _FLAG.search(node.value)
        )
    return sorted(hits, key=lambda hit: (hit.split(":")[0], int(hit.split(":")[1])))


def stage_of(module: str, stages: Sequence[Sequence[str]]) -> tuple[int, str] | None:
    """Return the rank and name of the stage holding ``module`` (its longest listed prefix)."""
    best: tuple[int, str] | None = None
    for rank, row in enumerate(stages):
        for name in row:
            if (module == name or module.startswith(name + ".")) and (
                best is None or len(name) > len(best[1])
            ):
                best = (rank, name)
    return best


def upward_imports(
    root: Path, packages: Sequence[str], stages: Sequence[Sequence[str]]
) -> list[str]:
    """Return ``importer -> imported`` for every import into another stage not below it."""
    files = module_files(root, packages)
    found: list[str] = []
    for name, path in files.items():
        own = stage_of(name, stages)
        if own is None:
            found.append(f"{name}: in no stage")
            continue
        for target in sorted(imported_modules(path, name, files)):
            theirs = stage_of(target, stages)
            if theirs is None or (theirs[1] != own[1] and theirs[0] >= own[0]):
                found.append(f"{name} -> {target}")
    return found


def top_modules(root: Path, package: str) -> list[str]:
    """Return the modules (files, ``__init__`` included) at the top of ``package``."""
    return sorted(path.name for path in (root / package).glob("*.py"))


def http_leaks(
    root: Path, packages: Sequence[str], frameworks: Collection[str] = HTTP_MODULES
) -> list[str]:
    """Return ``module:line`` for every import of a web framework or raise of an HTTP error."""
    hits: list[str] = []
    for name, path in module_files(root, packages).items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            imported: list[str] = []
            if isinstance(node, ast.Import):
                imported = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                imported = [node.module or ""]
            raised = ""
            if isinstance(node, ast.Raise) and node.exc is not None:
                call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                raised = getattr(call, "id", None) or getattr(call, "attr", "")
            if any(n.split(".")[0] in frameworks for n in imported) or raised in HTTP_ERROR_NAMES:
                hits.append(f"{name}:{node.lineno}")
    return hits


def test_stages_import_only_downward() -> None:
    """Each stage folder imports only its own modules and lower stages (see STAGES)."""
    assert upward_imports(ROOT, CORE_PACKAGES, STAGES) == []


def test_service_stages_import_only_downward() -> None:
    """Each room of the service imports only its own modules, lower rooms and the core."""
    assert upward_imports(ROOT, PACKAGES, STAGES + SERVICE_STAGES) == []


def test_service_keeps_a_dozen_modules_at_its_top() -> None:
    """A newcomer finds each concern of the service (api, jobs, blobs, ...) as one folder."""
    top = top_modules(ROOT, "service")
    assert len(top) <= MAX_SERVICE_TOP_MODULES, top


def test_core_keeps_few_modules_at_its_top() -> None:
    """A newcomer finds each stage of the data flow as one folder of ``loceval/``."""
    top = top_modules(ROOT, "loceval")
    assert len(top) <= MAX_TOP_MODULES, top


def test_core_and_exporters_know_no_http() -> None:
    """Nothing under loceval/ or exporters/ imports a web framework or raises HTTP types."""
    assert http_leaks(ROOT, CORE_PACKAGES) == []


RESOURCE_MODULES: Final = (
    "service.uploads.datasets",
    "service.jobs.evaluations",
    "service.schedules.resource",
    "service.schedules.runs",
    "service.uploads.recordings",
    "service.jobs.executor",
    "service.jobs.runner",
)
"""The service's resource and job modules: below the routes, so they raise domain errors."""


def test_resource_modules_raise_no_http_types() -> None:
    """The service's resources raise domain errors; only the routes and adapters speak HTTP."""
    files = module_files(ROOT, ("service",))
    leaks = [
        hit
        for hit in http_leaks(ROOT, ("service",), ("fastapi", "starlette", "uvicorn"))
        if hit.split(":")[0] in RESOURCE_MODULES
    ]
    assert set(RESOURCE_MODULES) <= set(files)
    assert leaks == []


HTTP_FREE_ROOMS: Final = ("service.blobs", "service.uploads", "service.jobs", "service.errors")
"""Below the routes: the blob stores return what to send, the uploads read any body, the jobs
and the errors are plain; only ``service/api/`` (and the app) make responses."""


def test_storage_uploads_jobs_and_errors_import_no_web_framework() -> None:
    """No module under blobs/, uploads/, jobs/ or the errors imports FastAPI or Starlette."""
    files = module_files(ROOT, ("service",))
    rooms = [m for m in files if any(m == r or m.startswith(r + ".") for r in HTTP_FREE_ROOMS)]
    leaks = [
        hit
        for hit in http_leaks(ROOT, ("service",), ("fastapi", "starlette"))
        if hit.split(":")[0] in rooms
    ]
    assert len(rooms) > 20  # the rooms are there (a renamed folder would pass unchecked)
    assert leaks == []


RESULT_READER: Final = "loceval.results.document"
"""The one reader of the result document (``result.json``)."""
RESULT_KEYS: Final = frozenset({"ate", "rpe", "verdict", "estimates"})
"""Keys of the result document that only its reader reads."""
READ_KEYS: Final = RESULT_KEYS - {"estimates"}
"""Keys whose subscript read is a dig (a stored request's ``["estimates"]`` is no result)."""
NOT_RESULTS: Final = {
    "exporters.grasshopper.loceval_paths": "ate",
    "service.results.paths": "ate",
    "service.cli.submit": "verdict",
}
"""Modules that read such a key of another document: the Grasshopper script and the service's
reader of an evaluation's paths (for Hops) read the ATE runs of ``paths.3dm.json``'s paths,
not the result document; ``loceval submit`` prints the API's summary rows (their verdict)."""


def result_digs(root: Path, packages: Sequence[str]) -> list[str]:
    """Return ``module:line: how`` for every dict-digging read of a result key.

    ``x.get("ate")`` (any key of :data:`RESULT_KEYS`), ``x["ate"]`` read (not written) and
    any use of a helper named ``_dig``.
    """
    hits: list[str] = []
    for name, path in module_files(root, packages).items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            how = ""
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and node.args[0].value in RESULT_KEYS
                and NOT_RESULTS.get(name) != node.args[0].value
            ):
                how = f".get({node.args[0].value!r})"
            elif (
                isinstance(node, ast.Subscript)
                and isinstance(node.ctx, ast.Load)
                and isinstance(node.slice, ast.Constant)
                and node.slice.value in READ_KEYS
                and NOT_RESULTS.get(name) != node.slice.value
            ):
                how = f"[{node.slice.value!r}]"
            elif isinstance(node, ast.Name | ast.FunctionDef) and "_dig" in {
                getattr(node, "id", None),
                getattr(node, "name", None),
            }:
                how = "_dig"
            if how and name != RESULT_READER:
                hits.append(f"{name}:{node.lineno}: {how}")
    return hits


def test_the_result_document_is_read_only_through_its_reader() -> None:
    """No module digs the result document as a dict: loceval.results.document reads it."""
    assert result_digs(ROOT, ("service", "exporters")) == []


def test_no_import_cycle() -> None:
    """No module of loceval, exporters or service reaches itself through its imports."""
    cycles = import_cycles(ROOT, PACKAGES)
    assert cycles == [], "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_no_module_longer_than_600_lines() -> None:
    """Every module can be read in one sitting."""
    assert long_modules(ROOT, PACKAGES, MAX_MODULE_LINES) == {}


def test_no_core_message_names_a_flag() -> None:
    """Core and exporter strings name options by key, never by a command-line flag."""
    assert flag_strings(ROOT, CORE_PACKAGES) == []


def _write_tree(root: Path, files: Mapping[str, str]) -> Path:
    for relative, source in files.items():
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(source), encoding="utf-8")
    return root


_CLEAN_TREE: Final = {
    "core/__init__.py": "from core.a import A\nfrom core.sub import helper\n",
    "core/a.py": '"""Docstring naming --flag is fine."""\nimport core.b\nA = 1\n',
    "core/b.py": "# a comment naming --flag is fine\nfrom .sub import helper\nMSG = 'use 3--4'\n",
    "core/sub/__init__.py": "from .helper import run\n",
    "core/sub/helper.py": (
        "import numpy\nfrom core import errors\n\ndef run():\n"
        "    '''Run --it.'''\n    from core.errors import E\n    return E\n"
    ),
    "core/errors.py": (
        "class E(Exception):\n    msg = 'no flag <!--comment-->, ---x'\n"
        '    """An attribute docstring naming --flag is fine."""\n'
    ),
    "app/__init__.py": "",
    "app/cli.py": "import core\nfrom core.sub.helper import run\nHELP = '--verbose'\n",
}


class TestLayeringChecksOnFakeTrees:
    def test_clean_tree_passes_every_check(self, tmp_path: Path) -> None:
        """A tree with packages, relative imports and docstring flags has no finding."""
        root = _write_tree(tmp_path, _CLEAN_TREE)
        assert import_cycles(root, ("core", "app")) == []
        assert long_modules(root, ("core", "app"), 600) == {}
        assert flag_strings(root, ("core",)) == []

    def test_imports_are_resolved(self, tmp_path: Path) -> None:
        """Relative, submodule and function-level imports name the right modules."""
        root = _write_tree(tmp_path, _CLEAN_TREE)
        known = module_files(root, ("core", "app"))
        assert imported_modules(known["core.b"], "core.b", known) == {"core.sub.helper"}
        assert imported_modules(known["core.sub"], "core.sub", known) == {"core.sub.helper"}
        helper = imported_modules(known["core.sub.helper"], "core.sub.helper", known)
        assert helper == {"core.errors"}  # numpy is outside; `from core import errors`
        assert imported_modules(known["app.cli"], "app.cli", known) == {"core", "core.sub.helper"}

    def test_function_level_import_cycle_is_found(self, tmp_path: Path) -> None:
        """A cycle closed by an import inside a function counts."""
        tree = {
            **_CLEAN_TREE,
            "core/errors.py": "def late():\n    from core.a import A\n    return A\n",
        }
        root = _write_tree(tmp_path, tree)
        assert import_cycles(root, ("core", "app")) == [
            ["core.a", "core.b", "core.sub.helper", "core.errors", "core.a"]
        ]

    def test_relative_and_type_checking_cycle_is_found(self, tmp_path: Path) -> None:
        """A two-module cycle through a relative import under TYPE_CHECKING counts."""
        tree = {
            **_CLEAN_TREE,
            "core/errors.py": (
                "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import b\n"
            ),
            "core/b.py": "from core.errors import E\n",
        }
        root = _write_tree(tmp_path, tree)
        assert import_cycles(root, ("core",)) == [["core.b", "core.errors", "core.b"]]

    def test_upward_import_is_found(self, tmp_path: Path) -> None:
        """An import into a higher stage or a sibling, or a module in no stage, is named."""
        stages = (("core.errors",), ("core.sub",), ("core.b",), ("core.a",), ("core",))
        root = _write_tree(tmp_path, _CLEAN_TREE)
        assert upward_imports(root, ("core",), stages) == []
        siblings = (("core.errors",), ("core.sub",), ("core.a", "core.b"), ("core",))
        assert upward_imports(root, ("core",), siblings) == ["core.a -> core.b"]
        assert upward_imports(root, ("core",), stages[:-1]) == ["core: in no stage"]
        tree = {**_CLEAN_TREE, "core/sub/helper.py": "from core.a import A\n"}
        root = _write_tree(tmp_path, tree)
        assert upward_imports(root, ("core",), stages) == ["core.sub.helper -> core.a"]

    def test_http_types_are_found(self, tmp_path: Path) -> None:
        """An import of a web framework, or an HTTP error raised, is named with its line."""
        tree = {
            **_CLEAN_TREE,
            "core/a.py": "import fastapi\n",
            "core/b.py": "from x import y\n\ndef f():\n    raise y.HTTPException(400)\n",
        }
        root = _write_tree(tmp_path, tree)
        assert http_leaks(root, ("core",)) == ["core.a:1", "core.b:4"]

    def test_result_digs_are_found(self, tmp_path: Path) -> None:
        """``.get("ate")``, a read of ``["verdict"]`` and ``_dig`` are found; a write is not."""
        tree = {
            **_CLEAN_TREE,
            "core/a.py": "def f(d):\n    return d.get('ate'), d['verdict']\n",
            "core/b.py": "def _dig(d):\n    d['rpe'] = 1\n    return d.get('other')\n",
        }
        root = _write_tree(tmp_path, tree)
        assert result_digs(root, ("core",)) == [
            "core.a:2: .get('ate')",
            "core.a:2: ['verdict']",
            "core.b:1: _dig",
        ]

    def test_long_module_is_found(self, tmp_path: Path) -> None:
        """601 lines is too long; 600 is not."""
        tree = {**_CLEAN_TREE, "core/a.py": "x = 1\n" * 601, "core/b.py": "x = 1\n" * 600}
        root = _write_tree(tmp_path, tree)
        assert long_modules(root, ("core", "app"), 600) == {"core.a": 601}

    def test_flag_in_message_is_found(self, tmp_path: Path) -> None:
        """A flag in a plain or f-string message is found, with its module and line."""
        tree = {
            **_CLEAN_TREE,
            "core/errors.py": (
                "def fail(x):\n"
                "    msg = f'Bad {x!r}; choose a smaller --rpe-delta.'\n"
                "    raise ValueError(msg)\n"
                "HINT = 'pass --max-dt 0.1'\n"
            ),
        }
        root = _write_tree(tmp_path, tree)
        assert flag_strings(root, ("core",)) == [
            "core.errors:2: '; choose a smaller --rpe-delta.'",
            "core.errors:4: 'pass --max-dt 0.1'",
        ]
