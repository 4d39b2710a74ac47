"""The HTTP contract of comparisons: systems of evaluations and evo results side by side."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from service.schemas.base import Id, Printable, Strict, strict_schema

__all__ = [
    "ComparedItem",
    "ComparedResultPublic",
    "ComparisonCreate",
    "ComparisonPairPublic",
    "ComparisonPublic",
]


def _one_source(schema: dict[str, Any], cls: type[BaseModel] | None = None) -> None:
    """Declare the NUL-free texts and the rule of :meth:`ComparedItem._one_source`."""
    strict_schema(schema, cls)
    text, null = {"type": "string"}, {"type": "null"}
    schema["anyOf"] = [
        {
            "required": ["evaluation_id"],
            "properties": {"evaluation_id": text, "dataset_id": null},
        },
        {
            "required": ["dataset_id"],
            "properties": {"dataset_id": text, "evaluation_id": null, "estimate": null},
        },
    ]


class ComparedItem(Strict):
    """One system: an estimate of a succeeded evaluation, or an uploaded evo result zip.

    Exactly one of ``evaluation_id`` and ``dataset_id`` is given, and ``estimate`` only with
    an evaluation (the schema's ``anyOf``).
    """

    model_config = ConfigDict(json_schema_extra=_one_source)

    evaluation_id: Id | None = Field(default=None, description="a succeeded evaluation")
    estimate: Annotated[str, Field(min_length=1, max_length=120)] | None = Field(
        default=None,
        description="the evaluation's estimate, by name (may be left out when it has one)",
    )
    dataset_id: Id | None = Field(
        default=None, description="an uploaded evo result zip (a dataset of kind evo_result)"
    )
    label: Annotated[str, Field(min_length=1, max_length=120), Printable] | None = Field(
        default=None, description="the name in the answer (default: the estimate's name)"
    )

    @model_validator(mode="after")
    def _one_source(self) -> ComparedItem:
        if (self.evaluation_id is None) == (self.dataset_id is None):
            msg = "give either evaluation_id (with estimate) or dataset_id (an evo result zip)"
            raise ValueError(msg)
        if self.dataset_id is not None and self.estimate is not None:
            msg = "estimate names an evaluation's estimate; an evo result zip holds one system"
            raise ValueError(msg)
        return self


class ComparisonCreate(Strict):
    """Systems to compare on one figure, each from an evaluation or an evo result zip."""

    items: Annotated[list[ComparedItem], Field(min_length=2, max_length=20)]
    metric: Literal["ate_rmse", "rpe_rmse"] = Field(
        default="ate_rmse",
        description="the RMSE compared: of the ATE or of the RPE, translation in metres",
    )


class ComparedResultPublic(BaseModel):
    """One system's figures and where they come from."""

    label: str
    source: Literal["loceval", "evo"]
    evaluation_id: str | None
    dataset_id: str | None
    title: str = Field(description="what the figures are (evo's title for an evo result)")
    stats: dict[str, float | None] = Field(
        description="rmse, mean, median, std, min, max, sse (metres)"
    )
    n: int | None
    ci95: dict[str, list[float]] | None = Field(
        description="95 % intervals of rmse, mean, median (loceval's); null where the source "
        "gives none (evo)"
    )
    intervals: str = Field(description="whether the source gives intervals, in words")


class ComparisonPairPublic(BaseModel):
    """Two systems' RMSEs compared on their paired instants, or why they are not."""

    a: str
    b: str
    difference: float | None = None
    ci95: list[float] | None = None
    verdict: Literal["a_better", "b_better", "within_noise"] | None = None
    n_common: int | None = None
    summary: str
    unavailable: str | None = Field(
        default=None, description="why there is no paired interval (then the others are null)"
    )


class ComparisonPublic(BaseModel):
    """The systems side by side and every pair compared (A before B, in the order given)."""

    metric: Literal["ate_rmse", "rpe_rmse"]
    items: list[ComparedResultPublic]
    comparisons: list[ComparisonPairPublic]
    notes: list[str]
