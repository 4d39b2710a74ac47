"""The HTTP contract: request and response bodies (``XCreate`` / ``XPublic`` / ``XsPublic``).

The schedules' bodies are in :mod:`service.schemas.schedules`.
"""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING, Annotated, Any, Final, Literal, cast

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    ValidationError,
    create_model,
    field_validator,
)
from pydantic_core import core_schema

from exporters import ARTIFACT_ALIASES, ARTIFACTS, artifact_name
from exporters.errors import ExportOptionsError
from loceval.options import AUTO, OPTIONS, OptionKind, OptionSpec, option
from service.schemas.base import Declared, Id, Printable, Strict, strict_schema

__all__ = [
    "ArtifactPublic",
    "DatasetFields",
    "DatasetPublic",
    "DatasetUploaded",
    "DatasetsPublic",
    "DeviceOffset",
    "EstimateRef",
    "EvaluationCreate",
    "EvaluationOptions",
    "EvaluationPublic",
    "EvaluationsPublic",
    "GatePublic",
    "OptionPublic",
    "OptionsPublic",
    "Problem",
    "ProgressPublic",
    "RangingCreate",
    "RangingOptions",
    "SourceRef",
    "SummaryRow",
    "UploadPublic",
    "options_public",
]

_Finite = Annotated[float, Field(allow_inf_nan=False)]


class Problem(BaseModel):
    """An error, as ``application/problem+json`` (RFC 9457)."""

    model_config = ConfigDict(extra="allow")

    type: str = Field(examples=["input.unreadable"])
    title: str = Field(examples=["ReaderError"])
    status: int = Field(examples=[422])
    detail: str = Field(examples=["run.mcap: no topic '/odom'; the bag has /amcl_pose, /tf."])


class SourceRef(Strict):
    """A trajectory in an uploaded dataset."""

    dataset_id: Id
    selector: Annotated[str, Field(min_length=1, max_length=500)] | None = Field(
        default=None,
        description="topic, tf:PARENT:CHILD or rigid body; null for a plain trajectory file",
        examples=["/amcl_pose", "tf:map:base_link"],
    )
    name: Annotated[str, Field(min_length=1, max_length=120)] | None = Field(
        default=None, description="name in the report (default: selector or file name)"
    )


class EstimateRef(SourceRef):
    """An estimate in an uploaded dataset, and the system it may be a trial of."""

    system: Annotated[str, Field(min_length=1, max_length=120), Printable] | None = Field(
        default=None,
        description="the system this estimate is a trial (a run) of; the estimates of one "
        "system are grouped, summarised over their trials and compared",
    )


class DeviceOffset(Strict):
    """The rigid body -> sensor offset read from an uploaded URDF or bag (``/tf_static``)."""

    dataset_id: Id
    from_link: Annotated[str, Field(min_length=1, max_length=200)]
    to_link: Annotated[str, Field(min_length=1, max_length=200)]


class MapRef(Strict):
    """An occupancy grid map in an uploaded dataset: a map zip, or a bag and its topic."""

    dataset_id: Id
    selector: Annotated[str, Field(min_length=1, max_length=500)] | None = Field(
        default=None,
        description="the bag's nav_msgs/msg/OccupancyGrid topic; null for a map zip",
        examples=["/map"],
    )


class _Choices:
    """``Annotated`` metadata: the value is one of the option's choices (a JSON ``enum``)."""

    def __init__(self, key: str) -> None:
        self.choices = [str(c) for c in option(key).choices]

    def __get_pydantic_core_schema__(
        self, _source: type[Any], _handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.literal_schema(self.choices)


def _bounds(key: str) -> Any:  # noqa: ANN401  (pydantic's FieldInfo, typed Any by pydantic)
    """Return the bounds of a number (or of each item of a list) of the options table."""
    spec = option(key)
    if spec.exclusive_minimum:
        return Field(allow_inf_nan=False, gt=spec.minimum, le=spec.maximum)
    return Field(allow_inf_nan=False, ge=spec.minimum, le=spec.maximum)


def _field(key: str) -> Any:  # noqa: ANN401  (pydantic's FieldInfo, typed Any by pydantic)
    """Return the field of an option: default, description, bounds, lengths and example."""
    spec = option(key)
    extra: dict[str, Any] = {}
    if spec.kind in {OptionKind.NUMBER, OptionKind.INTEGER} and not spec.auto:
        extra["le"] = spec.maximum
        extra["gt" if spec.exclusive_minimum else "ge"] = spec.minimum
    if spec.kind is OptionKind.NUMBER and not spec.auto:
        extra["allow_inf_nan"] = False
    if spec.kind in {OptionKind.TEXT, OptionKind.NUMBERS, OptionKind.NAMES}:
        extra["max_length"] = spec.max_length
    if spec.kind is OptionKind.NAMES:
        extra["min_length"] = spec.min_length
    if spec.example is not None:
        extra["examples"] = [spec.example]
    default = list(spec.default) if isinstance(spec.default, tuple) else spec.default
    return Field(default=default, description=spec.help, **extra)  # pydantic copies a list


class _OrAuto:
    """``Annotated`` metadata: the value is ``inner``'s, or ``"auto"`` (estimated from the data).

    Validation runs ``inner`` as it is (its errors name the field, not a union branch); the
    JSON schema is ``anyOf [inner, {"const": "auto"}]``.
    """

    def __init__(self, inner: Any, words: str) -> None:  # noqa: ANN401  (a type expression)
        self.inner = inner
        self.words = words

    def __get_pydantic_core_schema__(
        self, _source: type[Any], handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        words = self.words

        def validate(value: object, inner: core_schema.ValidatorFunctionWrapHandler) -> object:
            if value == AUTO:
                return AUTO
            try:
                return inner(value)
            except ValidationError:
                if isinstance(value, str):
                    msg = f"takes {words} or {AUTO!r}, got {value!r}"
                    raise ValueError(msg) from None  # noqa: TRY004  (pydantic wants ValueError)
                raise

        def serialize(value: object, inner: core_schema.SerializerFunctionWrapHandler) -> object:
            return AUTO if value == AUTO else inner(value)

        inner_schema = handler.generate_schema(self.inner)
        return core_schema.no_info_wrap_validator_function(
            validate,
            inner_schema,
            json_schema_input_schema=core_schema.union_schema(
                [inner_schema, core_schema.literal_schema([AUTO])]
            ),
            serialization=core_schema.wrap_serializer_function_ser_schema(
                serialize, schema=inner_schema
            ),
        )


_Device = Annotated[
    DeviceOffset | Literal["auto"] | None,
    _OrAuto(DeviceOffset | None, "a device file's dataset and links"),
]

_Matrix4 = Annotated[
    list[Annotated[list[_Finite], Field(min_length=4, max_length=4)]],
    Field(min_length=4, max_length=4),
]
_Artifact = Annotated[str, Field(max_length=40, json_schema_extra={"enum": list(ARTIFACTS)})]
_Name = Annotated[str, Field(min_length=1, max_length=200)]

_API_SHAPES: Final[dict[str, Any]] = {
    "formats": list[_Artifact] | None,
    "map": MapRef | None,
}
"""The options whose API shape is not their kind's: artifact names; a map's dataset and topic."""

_KIND_TYPES: Final[dict[OptionKind, Any]] = {
    OptionKind.NUMBER: float,
    OptionKind.INTEGER: int,
    OptionKind.TEXT: str,
    OptionKind.FILE: str,  # the API names an uploaded dataset by its id
    OptionKind.MATRIX: _Matrix4,
}
"""The JSON type of each kind whose type needs nothing of the option itself."""


def _base_type(spec: OptionSpec) -> Any:  # noqa: ANN401  (a type expression)
    """Return the JSON type of one value of an option, from its kind."""
    if spec.kind is OptionKind.CHOICE:
        return Annotated[str, _Choices(spec.key)]
    if spec.kind is OptionKind.NUMBERS:
        return list[Annotated[float, _bounds(spec.key)]]
    if spec.kind is OptionKind.NAMES:
        item = Literal.__getitem__(spec.choices) if spec.choices else _Name
        return list[item]  # type: ignore[valid-type]
    if spec.kind is OptionKind.TEXT and spec.pattern is not None:
        # Declared, not checked here: the service checks it after the option's parser
        # (loceval.options.check_pattern), so a bad value gets the parser's message.
        return Annotated[str, Declared(pattern=spec.pattern)]
    return _KIND_TYPES[spec.kind]


def _annotation(spec: OptionSpec) -> Any:  # noqa: ANN401  (a type expression)
    """Return the JSON type of an option: its kind's, or ``auto``, or null when not set."""
    if spec.key in _API_SHAPES:
        return _API_SHAPES[spec.key]
    if spec.kind is OptionKind.SWITCH:
        return bool
    if spec.kind is OptionKind.DEVICE:
        return _Device
    base = _base_type(spec)
    if spec.auto:
        inner = Annotated[base, _bounds(spec.key)] if spec.kind is OptionKind.NUMBER else base
        base = Annotated[base | Literal["auto"], _OrAuto(inner, _other_than_auto(spec))]
    return base | None if spec.default is None else base


def _other_than_auto(spec: OptionSpec) -> str:
    """Return how the message of a bad ``auto`` option names the other value it takes."""
    if spec.kind is not OptionKind.NUMBER:
        return f"{spec.words} as {spec.metavar or 'text'}"
    unit = {"_s": " of seconds", "_m": " of metres"}.get(spec.key[-2:], "")
    return f"a number{unit}"


def _fields(group: str) -> dict[str, Any]:
    """Return ``create_model``'s fields of the API's options of a group of the table."""
    wanted = (
        {"ranging"}
        if group == "ranging"
        else {"evaluation", "reading", "export", "map", "baseline"}
    )
    return {
        spec.key: (_annotation(spec), _field(spec.key))
        for spec in OPTIONS
        if spec.api and spec.group in wanted
    }


if TYPE_CHECKING:  # the fields are made from the table at run time; typed by key here

    class _EvaluationFields(Strict):
        def __getattr__(self, key: str) -> Any: ...  # noqa: ANN401

else:
    _EvaluationFields = create_model("_EvaluationFields", __base__=Strict, **_fields("evaluation"))


def _given(key: str) -> dict[str, Any]:
    """Return the JSON schema of an object in which option ``key`` is given (not null, not "")."""
    value = {"type": "string", "minLength": 1} if option(key).kind is OptionKind.TEXT else {}
    return {"required": [key], "properties": {key: {**value, "not": {"type": "null"}}}}


def _both(first: str, second: str) -> dict[str, Any]:
    """Return the JSON schema of an object in which both options are given."""
    a, b = _given(first), _given(second)
    return {"required": [first, second], "properties": {**a["properties"], **b["properties"]}}


def _options_schema(schema: dict[str, Any], cls: type[BaseModel] | None = None) -> None:
    """Declare the NUL-free texts and the pairs of options that exclude each other."""
    strict_schema(schema, cls)
    schema["not"] = {"anyOf": [_both("offset", "device"), _both("site", "site_matrix")]}


def _ranging_schema(schema: dict[str, Any], cls: type[BaseModel] | None = None) -> None:
    """Declare, on top of the evaluation's rules, what a ranging evaluation does not take."""
    strict_schema(schema, cls)
    schema["not"] = {
        "anyOf": [_both("site", "site_matrix"), _given("offset"), _given("device"), _given("map")]
    }


class EvaluationOptions(_EvaluationFields):
    """The evaluation options, as ``POST /evaluations`` takes them.

    Its fields are made from :data:`loceval.options.OPTIONS` (the CLI's flags are made from
    the same table): each option's key, JSON type (from its kind), default, bounds, choices,
    example and help. An option added to the table is here with no other edit.

    The schema also says which options exclude each other (``not``): a device offset given
    both as ``offset`` and as ``device``, a site given both as ``site`` and ``site_matrix``.
    The service checks these with the options' messages (422).
    """

    model_config = ConfigDict(json_schema_extra=_options_schema)

    @property
    def map_ref(self) -> MapRef | None:
        """Return the map's dataset and bag topic (None without a map)."""
        return cast("MapRef | None", self.map)

    @field_validator("map", mode="before", check_fields=False)
    @classmethod
    def _map_id(cls, value: object) -> object:
        """Take a bare dataset id (a map zip) as ``{"dataset_id": id}``."""
        return {"dataset_id": value} if isinstance(value, str) else value

    @field_validator("formats", check_fields=False)
    @classmethod
    def _known_formats(cls, value: list[str] | None) -> list[str] | None:
        """Accept file names and format aliases (``dxf``, ``pdf``, ``glb``); store file names."""
        if value is None:
            return None
        names = []
        for v in value:  # at most 20
            try:
                names.append(artifact_name(v))
            except ExportOptionsError:
                aliases = ", ".join(ARTIFACT_ALIASES)
                msg = (
                    f"unknown artifact {v!r}; choose from {', '.join(ARTIFACTS)}, or a format "
                    f"({aliases})"
                )
                raise ValueError(msg) from None
        return list(dict.fromkeys(names))


class EvaluationCreate(Strict):
    """A new evaluation: a reference, the estimates, and options."""

    reference: SourceRef
    estimates: Annotated[list[EstimateRef], Field(min_length=1, max_length=20)]
    options: EvaluationOptions = Field(default_factory=EvaluationOptions)


if TYPE_CHECKING:

    class _RangingFields(EvaluationOptions): ...

else:
    _RangingFields = create_model(
        "_RangingFields", __base__=EvaluationOptions, **_fields("ranging")
    )


class RangingOptions(_RangingFields):
    """The options of ``POST /ranging``: the evaluation's, then the ranging ones (from the table).

    The alignment defaults to ``none``: the anchors are in building coordinates already.
    A device offset (``offset``, ``device``) is refused: the tag offset says where the tag is;
    so is a map (measured in trajectory evaluations). The schema says so (``not``).
    """

    model_config = ConfigDict(json_schema_extra=_ranging_schema)

    align: Annotated[str, _Choices("align")] = Field(
        default="none", description=option("align").help
    )


class RangingCreate(Strict):
    """A new ranging evaluation: a reference, the anchors and the ranges (uploaded datasets)."""

    reference: SourceRef
    anchors: Id = Field(description="the dataset of the anchors table (id,x,y,z)")
    ranges: Id | SourceRef = Field(
        description=(
            "the dataset of the ranges table (t,anchor_id,range_m), or {dataset_id, selector} "
            "for a bag's sensor_msgs/msg/Range topic"
        )
    )
    options: RangingOptions = Field(default_factory=RangingOptions)

    @property
    def ranges_ref(self) -> SourceRef:
        """The ranges as a dataset and selector."""
        if isinstance(self.ranges, SourceRef):
            return self.ranges
        return SourceRef(dataset_id=self.ranges)


class DatasetPublic(BaseModel):
    """An uploaded recording and what it holds."""

    id: str
    name: str
    filename: str
    kind: str = Field(examples=["rosbag2-mcap"])
    size_bytes: int
    sha256: str
    tags: list[str]
    created_at: dt.datetime
    inspection: dict[str, Any] = Field(
        description="kind, sources (selector, description, pose_count, ...), topics, tf_tree"
    )


MAX_DATASET_NAME: Final = 300
MAX_TAG: Final = 50
MAX_TAGS: Final = 20


class DatasetFields(Strict):
    """The text fields of ``POST /datasets``: checked, never cut to fit."""

    name: Annotated[str, Field(min_length=1, max_length=MAX_DATASET_NAME), Printable] | None = None
    tags: Annotated[
        list[Annotated[str, Field(min_length=1, max_length=MAX_TAG), Printable]],
        Field(max_length=MAX_TAGS),
    ] = Field(default_factory=list)


class UploadPublic(BaseModel):
    """What ``POST /datasets`` did with this request's file name, name and tags."""

    deduplicated: bool = Field(
        description="these bytes were uploaded to this project before: the answer is that "
        "dataset (status 200, not 201); nothing new is stored"
    )
    tags_added: list[str] = Field(
        description="this request's tags that the dataset did not have; they were added "
        "(the tags of identical uploads merge)"
    )
    name_kept: str | None = Field(
        default=None,
        description="deduplicated, and the request named the dataset otherwise: the "
        "dataset keeps this name and the request's name is not applied",
    )
    notes: list[str] = Field(
        description="in words, everything the server did not take as sent (file name "
        "sanitised or shortened, name kept, tags merged)"
    )


class DatasetUploaded(DatasetPublic):
    """The answer to an upload: the dataset, and what became of the request's fields."""

    upload: UploadPublic


class DatasetsPublic(BaseModel):
    """A page of datasets, newest first."""

    items: list[DatasetPublic]
    count: int


class ProgressPublic(BaseModel):
    """Where a job is."""

    stage: str
    fraction: float


class SummaryRow(BaseModel):
    """Headline figures of one estimate."""

    name: str | None
    ate_rmse_m: float | None
    rpe_rmse_m: float | None
    matched: int | None
    verdict: Literal["pass", "fail", "undecided"] | None


class GatePublic(BaseModel):
    """The gate of ``options.fail_on``: what a CI job checks before it lets a change through."""

    passed: bool = Field(description="no condition of fail_on holds (the CLI exits 0; else 3)")
    fail_on: list[Literal["fail", "undecided", "worse"]] = Field(
        description="the conditions judged, in the order fail, undecided, worse"
    )
    reasons: list[str] = Field(
        description="one sentence per estimate and condition that holds, with the figures",
        examples=[["ORB-SLAM3 fails the tolerance (87.2 % within 0.10 m, needs 95 %)"]],
    )


class ArtifactPublic(BaseModel):
    """A downloadable file of a succeeded evaluation."""

    name: str
    media_type: str
    size_bytes: int
    url: str
    filename: str = Field(
        description="the name a download is saved under (its Content-Disposition): the "
        "evaluation's estimates' names, or its id, then the artifact's name"
    )


class EvaluationPublic(BaseModel):
    """An evaluation job: status, progress, and the result once it succeeded."""

    id: str
    status: Literal["queued", "running", "succeeded", "failed"]
    progress: ProgressPublic
    attempts: int
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    reference: SourceRef
    estimates: list[EstimateRef]
    options: dict[str, Any]
    summary: list[SummaryRow] | None = None
    error: Problem | None = None
    artifacts: list[ArtifactPublic] | None = None
    result: dict[str, Any] | None = Field(
        default=None, description="the CLI's --json document (GET of one evaluation only)"
    )
    gate: GatePublic | None = Field(
        default=None,
        description="the gate of options.fail_on, judged from result as the CLI judges its own "
        "(GET of one evaluation only, once result is there; null without fail_on)",
    )


class EvaluationsPublic(BaseModel):
    """A page of evaluations, newest first (without the result documents)."""

    items: list[EvaluationPublic]
    count: int


class OptionPublic(BaseModel):
    """One option of ``POST /evaluations`` and ``POST /ranging`` (a row of the table)."""

    key: str = Field(examples=["max_dt_s"])
    kind: Literal[tuple(OptionKind)] = Field(  # type: ignore[valid-type]
        description="the type of the value: number, integer, switch, choice, text, numbers, "
        "names, matrix, device or file (an uploaded dataset's id)"
    )
    default: Any = Field(description="the value when not given (null: not set)")
    help: str
    words: str = Field(description="how messages name the option")
    flag: str | None = Field(description="the CLI's flag of the same option")
    metavar: str | None
    minimum: float | None = Field(description="the least value (of each item, for lists)")
    maximum: float | None = Field(description="the greatest value (of each item, for lists)")
    exclusive_minimum: bool = Field(description="the minimum itself is not allowed")
    choices: list[str]
    max_length: int | None
    min_length: int | None
    pattern: str | None
    example: str | None
    group: Literal["evaluation", "reading", "export", "map", "baseline", "ranging"] = Field(
        description="ranging: only POST /ranging takes it"
    )
    auto: bool = Field(description='the value may also be "auto" (estimated from the data)')
    bounds: str = Field(description="the allowed range in words", examples=["more than 0"])
    bounds_hint: str = Field(
        description="the bounds a person would type, for a form's hint (1e+09 left out)",
        examples=["at least 0"],
    )
    label: str = Field(description="the option's short name on a form", examples=["Max gap (s)"])


class OptionsPublic(BaseModel):
    """Every option the API takes, in the order of the schema (one table makes both)."""

    items: list[OptionPublic]


def options_public() -> OptionsPublic:
    """Return the options document: the rows of :data:`loceval.options.OPTIONS` the API takes."""
    return OptionsPublic.model_validate(
        {"items": [spec.document() for spec in OPTIONS if spec.api]}
    )
