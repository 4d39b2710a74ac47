"""``/api/v1/comparisons``: systems of evaluations and uploaded evo results, side by side."""

from __future__ import annotations

from fastapi import APIRouter

from service.api.deps import ProjectDep, RuntimeDep
from service.api.responses import problems
from service.results import comparisons
from service.schemas.comparisons import ComparisonCreate, ComparisonPublic

__all__ = ["router"]

router = APIRouter(prefix="/comparisons", tags=["comparisons"])


@router.post("", response_model=ComparisonPublic, responses=problems(404, 409, 507))
def create_comparison(
    body: ComparisonCreate, runtime: RuntimeDep, project_id: ProjectDep
) -> ComparisonPublic:
    """Compare estimates of evaluations and uploaded evo result zips on one RMSE, pair by pair.

    Nothing is stored, but an evo zip in object storage is first copied into this machine's
    read cache: with its disk full the answer is 507.
    """
    return comparisons.compare_items(runtime, project_id, body)
