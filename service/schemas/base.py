"""What every request body shares: the strict base model, the id type and the printable check.

:mod:`service.schemas.evaluations` and :mod:`service.schemas.schedules` build their request
bodies on these.
"""

from __future__ import annotations

from typing import Annotated, Any, Final

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    GetJsonSchemaHandler,
    field_validator,
)
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import PydanticCustomError, core_schema

__all__ = ["NO_NUL", "PRINTABLE", "Declared", "Id", "Printable", "Strict", "strict_schema"]

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


def _declare_no_nul(schema: dict[str, Any]) -> None:
    """Give every text of a JSON schema without a pattern, enum or const the NUL-free pattern.

    Walks the schema of one model (``anyOf``, ``items``, ``properties``...), not the models
    it refers to (``$ref``): those are :class:`Strict` too and declare their own. A text
    that already has a pattern keeps it; each such pattern excludes NUL itself.
    """
    if schema.get("type") == "string" and not schema.keys() & {"pattern", "enum", "const"}:
        schema["pattern"] = NO_NUL
    for value in schema.values():
        if isinstance(value, dict):
            _declare_no_nul(value)
        elif isinstance(value, list):
            for item in value:
                if isinstance(item, dict):
                    _declare_no_nul(item)


def strict_schema(schema: dict[str, Any], _cls: type[BaseModel] | None = None) -> None:
    """Declare the NUL-free pattern on every text property of a model's JSON schema.

    The ``json_schema_extra`` of :class:`Strict`; a subclass that has its own calls this.
    """
    for prop in schema.get("properties", {}).values():
        _declare_no_nul(prop)


class Strict(BaseModel):
    """A request body: unknown fields and NUL characters in any text are refused.

    No text a client sends is meant to hold NUL, and PostgreSQL cannot store one (the
    request would fail with a 500 at the database instead of a 422 naming the field).
    The JSON schema says so: every text field declares the pattern :data:`NO_NUL` (or a
    stricter one), while the check stays here, so its message names the NUL.
    """

    model_config = ConfigDict(extra="forbid", json_schema_extra=strict_schema)

    @field_validator("*", mode="after")
    @classmethod
    def _no_nul(cls, value: Any) -> Any:  # noqa: ANN401  (every field's type)
        if _holds_nul(value):
            msg = "holds a NUL character (\\u0000); remove it"
            raise PydanticCustomError("nul_character", msg)  # noqa: EM101  (the error type)
        return value


PRINTABLE: Final = r"^[^\x00-\x1f\x7f]*$"
"""The pattern of a text without control characters (tab, newline, NUL, DEL...)."""


def _printable(value: str) -> str:
    """Refuse control characters (a database may not store them, a page cannot show them)."""
    if any(ord(c) < 0x20 or ord(c) == 0x7F for c in value):
        msg = "holds control characters (tab, newline, NUL, ...); remove them"
        raise PydanticCustomError("control_characters", msg)  # noqa: EM101  (the error type)
    return value


class _Printable:
    """``Annotated`` metadata: no control characters; checked here, declared as a pattern."""

    def __get_pydantic_core_schema__(
        self, source: type[Any], handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(_printable, handler(source))

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        json_schema = handler(schema)
        json_schema["pattern"] = PRINTABLE
        return json_schema


Printable = _Printable()
"""Annotate a ``str`` field with this to refuse control characters in it."""


class Declared:
    """``Annotated`` metadata: JSON schema keywords the service checks itself, with its words.

    For a rule the service checks after validation (a cron line, a time zone, an option's
    grammar) so that a bad value gets its own message rather than pydantic's; the schema
    still says exactly what is taken (``Declared(pattern=...)``, ``Declared(enum=[...])``).
    """

    def __init__(self, **keywords: object) -> None:
        """Keep the keywords to add to the field's JSON schema."""
        self.keywords = keywords

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        """Return the field's JSON schema with the keywords added."""
        json_schema = handler(schema)
        json_schema.update(self.keywords)
        return json_schema
