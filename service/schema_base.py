"""What every request body shares: the strict base model, the id type and the printable check.

:mod:`service.schemas` and :mod:`service.schedule_schemas` build their request bodies on
these.
"""

from __future__ import annotations

from typing import Annotated, Any, Final

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator
from pydantic_core import PydanticCustomError

__all__ = ["NO_NUL", "Id", "Printable", "Strict"]

NO_NUL: Final = r"^[^\x00]*$"
"""The pattern of a text that holds no NUL character (the OpenAPI document says so)."""

Id = Annotated[str, Field(min_length=1, max_length=64, examples=["0b8e6c1e-..."])]
"""The id of a stored dataset, evaluation or schedule, as a client sends it."""


def _holds_nul(value: object) -> bool:
    if isinstance(value, str):
        return "\x00" in value
    if isinstance(value, list | tuple):
        return any(_holds_nul(v) for v in value)
    if isinstance(value, dict):
        return any(_holds_nul(k) or _holds_nul(v) for k, v in value.items())
    return False


class Strict(BaseModel):
    """A request body: unknown fields and NUL characters in any text are refused.

    No text a client sends is meant to hold NUL, and PostgreSQL cannot store one (the
    request would fail with a 500 at the database instead of a 422 naming the field).
    """

    model_config = ConfigDict(extra="forbid")

    @field_validator("*", mode="after")
    @classmethod
    def _no_nul(cls, value: Any) -> Any:  # noqa: ANN401  (every field's type)
        if _holds_nul(value):
            msg = "holds a NUL character (\\u0000); remove it"
            raise PydanticCustomError("nul_character", msg)  # noqa: EM101  (the error type)
        return value


def _printable(value: str) -> str:
    """Refuse control characters (a database may not store them, a page cannot show them)."""
    if any(ord(c) < 0x20 or ord(c) == 0x7F for c in value):
        msg = "holds control characters (tab, newline, NUL, ...); remove them"
        raise PydanticCustomError("control_characters", msg)  # noqa: EM101  (the error type)
    return value


Printable = AfterValidator(_printable)
"""Annotate a ``str`` field with this to refuse control characters in it."""
