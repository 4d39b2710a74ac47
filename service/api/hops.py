r"""Grasshopper Hops endpoint: the paths of an evaluation as Rhino curves in a definition.

It speaks the protocol of Rhino's Hops component (as ``ghhops-server`` serves it):

- ``GET /hops/`` lists the components, ``GET /hops/<name>`` describes one: ``Uri``,
  ``Name``, ``Nickname``, ``Description``, ``Category``, ``Subcategory``, and ``Inputs`` /
  ``Outputs`` as ``{Name, Nickname, Description, ParamType, ResultType, AtLeast, AtMost}``;
- a solve is a ``POST /solve`` at the server's root (where the Hops client posts it) with
  ``pointer`` = the component's uri (``hops/paths``, with or without the leading slash);
  ``POST /hops/solve`` and ``POST /hops/<name>`` are accepted too. Inputs arrive as
  ``values: [{ParamName, InnerTree: {"{0}": [{type, data}]}}]``, a string's ``data``
  JSON-encoded with its quotes (``"\\"3f2a...\\""``) as the real client sends it.
- The answer is ``{values: [{ParamName, InnerTree}], errors, warnings}``: one tree branch
  ``{k}`` per trajectory. Curves are ``Rhino.Geometry.PolylineCurve`` items whose ``data``
  is the JSON of rhino3dm's ``CommonObject.Encode()`` (what ``CommonObject.FromJSON``
  decodes in Grasshopper); strings and numbers are JSON-encoded.

Hops sends the key of its preferences in the ``RhinoComputeKey`` header: a project key is
accepted there (or as ``Authorization: Bearer``). Listing and describing need no key.
A domain error (unknown evaluation, not finished, no such trajectory) comes back in the
protocol's ``errors`` list with its HTTP status, so the Hops component shows the message.

The curves are the ones the evaluation wrote to ``paths.3dm.json``: model coordinates in
the evaluation's units, the same vertices as ``paths.dxf``; the statistics are its result's.
Both are read by :func:`service.results.paths.read_paths`: this module only speaks Hops.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Annotated, Any, Final

import anyio.to_thread
from fastapi import APIRouter, Depends, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

from loceval.errors import InputError, LocevalError
from loceval.results.document import EstimateRead
from service.api.deps import RuntimeDep
from service.api.responses import problem_example, problems
from service.auth import authenticate
from service.errors import PROBLEM_JSON, AuthenticationError, NotFoundError, status_for
from service.results.paths import read_paths
from service.runtime import Runtime
from service.schemas import examples

__all__ = ["COMPONENTS", "router"]

router = APIRouter(tags=["hops"])

_PATHS_URI: Final = "/hops/paths"
_TREE: Final = {"AtLeast": -1, "AtMost": -1}  # a data tree: one branch per trajectory
_ITEM: Final = {"AtLeast": 1, "AtMost": 1}
_RHINO_UNITS: Final = {"mm": "Millimeters", "cm": "Centimeters", "m": "Meters"}
_MISSING_KEY: Final = (
    "This component needs a project key: enter it as the API key in Hops' preferences "
    "(sent as the RhinoComputeKey header); loceval keys create --project NAME prints one."
)
_UNKNOWN_KEY: Final = "The project key is unknown or revoked; ask your administrator for a new one."


def _param(
    name: str, nickname: str, description: str, param_type: str, result_type: str, **extra: object
) -> dict[str, Any]:
    return {
        "Name": name,
        "Nickname": nickname,
        "Description": description,
        "ParamType": param_type,
        "ResultType": result_type,
        **extra,
    }


COMPONENTS: Final[dict[str, dict[str, Any]]] = {
    "paths": {
        "Uri": _PATHS_URI,
        "Name": "loceval paths",
        "Nickname": "Paths",
        "Description": (
            "The reference and estimate paths of a loceval evaluation as polylines in "
            "model coordinates, with their colours and ATE/RPE statistics."
        ),
        "Category": "loceval",
        "Subcategory": "Evaluation",
        "Inputs": [
            _param(
                "Evaluation",
                "E",
                "the evaluation id (from the loceval web page or API)",
                "Text",
                "System.String",
                **_ITEM,
            ),
            _param(
                "Trajectory",
                "T",
                "a trajectory's name; empty for all of them",
                "Text",
                "System.String",
                **_ITEM,
                Default="",
            ),
        ],
        "Outputs": [
            _param(
                "Paths",
                "P",
                "one polyline per trajectory",
                "Curve",
                "Rhino.Geometry.Curve",
                **_TREE,
            ),
            _param("Names", "N", "the trajectories' names", "Text", "System.String", **_TREE),
            _param(
                "Colours", "C", "their colours as R,G,B (0-255)", "Text", "System.String", **_TREE
            ),
            _param(
                "ATE",
                "A",
                "ATE translation RMSE, metres (none for the reference)",
                "Number",
                "System.Double",
                **_TREE,
            ),
            _param(
                "ATE paths",
                "AP",
                "each estimate cut into runs of one error colour (none for the reference)",
                "Curve",
                "Rhino.Geometry.Curve",
                **_TREE,
            ),
            _param(
                "ATE colours",
                "AC",
                "the colour of each ATE run as R,G,B: the report's and the viewer's scale, "
                "green within the tolerance, orange to red beyond",
                "Text",
                "System.String",
                **_TREE,
            ),
            _param(
                "Statistics",
                "S",
                "kind, source, ATE/RPE statistics, verdict and colour legend as JSON",
                "Text",
                "System.String",
                **_TREE,
            ),
        ],
    },
}
"""The components, by name; each is described at ``GET /hops/<name>``."""


class HopsItem(BaseModel):
    """One value of a Hops data tree."""

    model_config = ConfigDict(extra="allow")
    type: str = Field(max_length=200)
    data: str = Field(max_length=100_000)


class HopsValue(BaseModel):
    """One input parameter: its name and data tree (``{"{0}": [item, ...]}``)."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)
    param_name: str = Field(alias="ParamName", max_length=200)
    inner_tree: dict[str, list[HopsItem]] = Field(alias="InnerTree")


class HopsSolve(BaseModel):
    """A Hops solve request (``absolutetolerance``, ``modelunits`` and the rest are kept)."""

    model_config = ConfigDict(extra="allow")
    pointer: str | None = Field(default=None, max_length=2000)
    values: list[HopsValue] = Field(default_factory=list, max_length=50)
    modelunits: str | None = Field(default=None, max_length=50)


class HopsAnswer(BaseModel):
    """A Hops solve answer: the output trees, and messages the component shows."""

    pointer: str | None = None
    values: list[dict[str, Any]]
    errors: list[str]
    warnings: list[str]


_HOPS_ANSWER: Final = {"$ref": "#/components/schemas/HopsAnswer"}


def _refused(message: str) -> dict[str, Any]:
    """Return Hops' own answer of a refused solve: no values, the message in ``errors``."""
    return {"values": [], "errors": [message], "warnings": []}


_REQUEST_INVALID: Final = {
    "type": "request.invalid",
    "title": "RequestValidationError",
    "status": 422,
    "detail": "The request is not valid: body.values: Input should be a valid list.",
    "errors": [
        {"loc": ["body", "values"], "msg": "Input should be a valid list", "type": "list_type"}
    ],
}
_SOLVE_RESPONSES: Final[dict[int | str, dict[str, Any]]] = {
    **problems(),
    422: {
        "description": "Hops' own answer (application/json: values, errors, warnings; the "
        "component shows the errors) when an input cannot be used; a problem document "
        "(application/problem+json) when the request itself is malformed",
        "content": {
            "application/json": {"schema": _HOPS_ANSWER, "example": examples.HOPS_REFUSED},
            PROBLEM_JSON: {
                "schema": {"$ref": "#/components/schemas/Problem"},
                "example": _REQUEST_INVALID,
            },
        },
    },
    **{
        status: {
            "description": f"{description}: Hops' own answer, the message in its errors",
            "content": {"application/json": {"schema": _HOPS_ANSWER, "example": example}},
        }
        for status, description, example in (
            (
                404,
                "no such evaluation in this key's project, or it wrote no paths.3dm.json",
                _refused(
                    "No evaluation '297a1e94-c86c-4e41-a598-ddbfae842cde' in this project; "
                    "list them with GET /evaluations."
                ),
            ),
            (
                409,
                "the evaluation has not succeeded (yet)",
                _refused(
                    "Evaluation '297a1e94-c86c-4e41-a598-ddbfae842cde' is running, so it has "
                    "no paths yet; solve again when it has succeeded."
                ),
            ),
        )
    },
}
_COMPONENT_RESPONSES: Final = problems(
    404,
    keyed=False,
    examples={
        404: problem_example(
            NotFoundError, 404, "No Hops component 'path'; the components are paths."
        )
    },
)


def hops_project(request: Request, runtime: RuntimeDep) -> str:
    """Return the project of the key in ``RhinoComputeKey`` (or ``Authorization: Bearer``).

    Raises:
        AuthenticationError: no key, or one that is unknown or revoked.
    """
    key = request.headers.get("rhinocomputekey", "").strip()
    if not key:
        scheme, _, credentials = request.headers.get("authorization", "").partition(" ")
        key = credentials.strip() if scheme.lower() == "bearer" else ""
    if not key:
        raise AuthenticationError(_MISSING_KEY)
    with runtime.sessions() as session:
        project_id = authenticate(session, key)
    if project_id is None:
        raise AuthenticationError(_UNKNOWN_KEY)
    return project_id


HopsProjectDep = Annotated[str, Depends(hops_project)]


@router.get("/hops", include_in_schema=False)
@router.get(
    "/hops/",
    responses={200: {"content": {"application/json": {"example": list(COMPONENTS.values())}}}},
)
def list_hops_components() -> list[dict[str, Any]]:
    """List the Grasshopper Hops components."""
    return list(COMPONENTS.values())


@router.get(
    "/hops/{name}",
    responses={
        200: {"content": {"application/json": {"example": COMPONENTS["paths"]}}},
        **_COMPONENT_RESPONSES,
    },
)
def read_hops_component(name: str) -> dict[str, Any]:
    """Describe one Hops component: its inputs and outputs."""
    return _component(name)


@router.post("/solve", response_model=HopsAnswer, responses=_SOLVE_RESPONSES)
@router.post("/hops/solve", response_model=HopsAnswer, include_in_schema=False)
async def solve_hops(
    body: HopsSolve, runtime: RuntimeDep, project_id: HopsProjectDep
) -> JSONResponse:
    """Solve the Hops component named by ``pointer`` (where Rhino's Hops client posts)."""
    name = (body.pointer or "").strip().strip("/").removeprefix("hops/")
    return await _solve(name, body, runtime, project_id)


@router.post("/hops/{name}", response_model=HopsAnswer, responses=_SOLVE_RESPONSES)
async def solve_hops_component(
    name: str, body: HopsSolve, runtime: RuntimeDep, project_id: HopsProjectDep
) -> JSONResponse:
    """Solve one Hops component at its own uri."""
    return await _solve(name, body, runtime, project_id)


async def _solve(name: str, body: HopsSolve, runtime: Runtime, project_id: str) -> JSONResponse:
    # the Hops protocol carries errors in its own document (the component shows them), so
    # domain errors are caught here instead of becoming problem+json
    try:
        _component(name)
        values, warnings = await anyio.to_thread.run_sync(_solve_paths, body, runtime, project_id)
    except LocevalError as err:
        failed = {"values": [], "errors": [str(err)], "warnings": []}
        return JSONResponse(failed, status_code=status_for(err))
    document: dict[str, object] = {
        "pointer": _PATHS_URI,
        "values": values,
        "errors": [],
        "warnings": warnings,
    }
    return JSONResponse(document)


def _component(name: str) -> dict[str, Any]:
    component = COMPONENTS.get(name.strip("/"))
    if component is None:
        msg = f"No Hops component {name!r}; the components are {', '.join(COMPONENTS)}."
        raise NotFoundError(msg)
    return component


def _inputs(body: HopsSolve) -> dict[str, str]:
    """Return each input's first item, a string's JSON quotes removed."""
    out: dict[str, str] = {}
    for value in body.values:
        items = [item for branch in value.inner_tree.values() for item in branch]
        if not items:
            continue
        data = items[0].data
        try:
            decoded = json.loads(data)
        except json.JSONDecodeError:
            decoded = data  # a client that sends the bare text
        out[value.param_name] = decoded if isinstance(decoded, str) else str(decoded)
    return out


def _solve_paths(
    body: HopsSolve, runtime: Runtime, project_id: str
) -> tuple[list[dict[str, Any]], list[str]]:
    inputs = _inputs(body)
    evaluation_id = inputs.get("Evaluation", "").strip()
    if not evaluation_id:
        msg = "The Evaluation input is empty; connect a panel with the evaluation's id."
        raise InputError(msg, option="Evaluation")
    found = read_paths(runtime, project_id, evaluation_id)
    paths = list(found.paths)
    wanted = inputs.get("Trajectory", "").strip()
    if wanted:
        paths = [p for p in paths if p["name"] == wanted]
        if not paths:
            names = ", ".join(repr(p["name"]) for p in found.paths)
            msg = (
                f"Evaluation {evaluation_id!r} has no trajectory {wanted!r}; its "
                f"trajectories are {names}."
            )
            raise InputError(msg, option="Trajectory")
    estimates = {e.name: e for e in found.result.estimates}
    warnings = []
    rhino_units = _RHINO_UNITS.get(found.units, found.units)
    if body.modelunits and body.modelunits.lower() != rhino_units.lower():
        warnings.append(
            f"The paths are in {rhino_units} (the evaluation's units) and this document is in "
            f"{body.modelunits}; scale them or evaluate with matching units."
        )
    trees: dict[str, dict[str, list[dict[str, str]]]] = {
        "Paths": {}, "Names": {}, "Colours": {}, "ATE": {}, "ATE paths": {}, "ATE colours": {},
        "Statistics": {},
    }  # fmt: skip
    for k, path in enumerate(paths):
        branch = f"{{{k}}}"
        estimate = estimates.get(path["name"])
        # One polyline per continuous piece: a path breaks at tracking loss (paths.3dm.json v2).
        trees["Paths"][branch] = [
            _item("Rhino.Geometry.PolylineCurve", curve) for curve in path["curves"]
        ]
        trees["Names"][branch] = [_item("System.String", path["name"])]
        trees["Colours"][branch] = [_item("System.String", ",".join(map(str, path["color"])))]
        ate = path.get("ate_translation_m")
        trees["ATE"][branch] = [] if not ate else [_item("System.Double", ate["rmse"])]
        # the runs paths.3dm.json carries, in the one error colour scale (exporters.colours)
        runs = found.ate_runs.get(path["name"], ())
        trees["ATE paths"][branch] = [
            _item("Rhino.Geometry.PolylineCurve", r["curve"]) for r in runs
        ]
        trees["ATE colours"][branch] = [
            _item("System.String", ",".join(map(str, r["color"]))) for r in runs
        ]
        statistics = {**_statistics(path, estimate), "ate_legend": found.ate_legend}
        trees["Statistics"][branch] = [_item("System.String", json.dumps(statistics))]
    values = [{"ParamName": name, "InnerTree": tree} for name, tree in trees.items()]
    return values, warnings


def _item(type_name: str, value: object) -> dict[str, str]:
    return {"type": type_name, "data": json.dumps(value)}


def _statistics(path: Mapping[str, Any], estimate: EstimateRead | None) -> dict[str, Any]:
    out = {
        "name": path["name"],
        "kind": path["kind"],
        "source": path["source"],
        "poses": path["poses"],
        "vertices": path["vertices"],
        "max_deviation_m": path["max_deviation_m"],
    }
    if estimate is not None:
        out.update(estimate.figures_as_written())
    return out
