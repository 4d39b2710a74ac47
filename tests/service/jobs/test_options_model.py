"""One options table: the CLI's flags and the API's schema both come from loceval.options."""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig
from loceval.options import OPTIONS, OptionKind, OptionSpec, check_option, option
from service.cli import describe
from service.cli.parser import RANGING_SKIPPED, build_parser
from service.errors import problem_for
from service.jobs.options import (
    config_from_options,
    export_from_options,
    ranging_from_options,
)
from service.schemas.base import NO_NUL
from service.schemas.evaluations import EvaluationOptions, RangingOptions

CLI_ONLY = {
    "help",
    "name",
    "system",
    "reference_name",
    "format",
    "json",
    "out",
    "device_from",
    "device_to",
}
"""The evaluate command's own arguments: how to run, not how to evaluate."""

RANGING_CLI_ONLY = {"help", "anchors", "ranges", "reference_name", "format", "json", "out"}
"""The ranging command's own arguments."""

ROOT = Path(__file__).parents[3]


def _evaluate_actions(command: str = "evaluate") -> dict[str, argparse.Action]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    evaluate = sub.choices[command]
    return {a.dest: a for a in evaluate._actions if a.option_strings}


def _api_properties(model: type[EvaluationOptions] = EvaluationOptions) -> dict[str, Any]:
    properties: dict[str, Any] = model.model_json_schema()["properties"]
    return properties


def _scalar(schema: dict[str, Any]) -> dict[str, Any]:
    """Return the non-null, non-``auto`` branch of a property (``anyOf [X, "auto", null]``)."""
    branches = [
        s
        for s in schema.get("anyOf", [schema])
        if s.get("type") != "null" and s.get("const") != "auto"
    ]
    assert len(branches) == 1, schema
    return dict(branches[0])


def _json_default(spec: OptionSpec) -> object:
    return list(spec.default) if isinstance(spec.default, tuple) else spec.default


def test_cli_flags_are_the_table() -> None:
    """Every evaluate flag but the command's own is an option: flag, key, default, choices."""
    actions = _evaluate_actions()
    cli_specs = [s for s in OPTIONS if s.cli and s.group != "ranging"]
    assert set(actions) - CLI_ONLY == {s.key for s in cli_specs}
    ranging_actions = _evaluate_actions("ranging")
    ranging_specs = [s for s in OPTIONS if s.cli and s.key not in RANGING_SKIPPED]
    assert set(ranging_actions) - RANGING_CLI_ONLY == {s.key for s in ranging_specs}
    assert ranging_actions["align"].default == "none"  # anchors are in building coordinates
    for spec in ranging_specs:
        assert ranging_actions[spec.key].option_strings == [spec.flag], spec.key
    for spec in cli_specs:
        action = actions[spec.key]
        assert action.option_strings == [spec.flag], spec.key
        assert action.default == spec.default, spec.key
        if spec.kind is OptionKind.CHOICE:
            assert list(action.choices or ()) == [str(c) for c in spec.choices], spec.key
        else:
            assert action.choices is None, spec.key
        assert spec.help in (action.help or ""), spec.key


def test_api_schema_is_the_table() -> None:
    """Every API option is a table option, in order, with its default, bounds and choices."""
    properties = _api_properties()
    api_specs = [s for s in OPTIONS if s.api and s.group != "ranging"]
    assert list(properties) == [s.key for s in api_specs]
    ranging_properties = _api_properties(RangingOptions)
    assert list(ranging_properties) == [s.key for s in OPTIONS if s.api]
    assert ranging_properties["align"]["default"] == "none"
    properties |= {k: v for k, v in ranging_properties.items() if k not in properties}
    for spec in (s for s in OPTIONS if s.api):
        prop = properties[spec.key]
        assert prop.get("default") == _json_default(spec), spec.key
        assert prop["description"] == spec.help, spec.key
        auto_branch = {"const": "auto", "type": "string"} in prop.get("anyOf", [])
        assert auto_branch == spec.auto, spec.key
        value = _scalar(prop)
        if spec.kind is OptionKind.NUMBERS:
            value = value["items"]
            assert _scalar(prop)["maxItems"] == spec.max_length, spec.key
        if spec.kind is OptionKind.CHOICE:
            assert value["enum"] == [str(c) for c in spec.choices], spec.key
        if spec.kind in {OptionKind.NUMBER, OptionKind.INTEGER, OptionKind.NUMBERS}:
            low = "exclusiveMinimum" if spec.exclusive_minimum else "minimum"
            assert value.get(low) == spec.minimum, spec.key
            assert value.get("maximum") == spec.maximum, spec.key
        if spec.kind is OptionKind.TEXT:
            assert value.get("maxLength") == spec.max_length, spec.key
            # A text without a grammar of its own is declared NUL-free (as the server holds it).
            assert value.get("pattern") == (spec.pattern or NO_NUL), spec.key


def test_both_front_doors_build_the_same_config() -> None:
    """CLI defaults and API defaults give the core's defaults, field for field."""
    args = build_parser().parse_args(["evaluate", "ref.txt", "est.txt"])
    from_cli = config_from_options(args)
    from_api = config_from_options(EvaluationOptions())
    assert from_cli == from_api == EvaluationConfig()
    assert args.stamp == EvaluationOptions().stamp == option("stamp").default


def _beyond(spec: OptionSpec) -> list[float]:
    """Return values just outside the option's bounds (the bound itself when exclusive)."""
    values = []
    if spec.maximum is not None:
        values.append(spec.maximum * 1.5 if spec.maximum > 0 else spec.maximum + 1)
    if spec.minimum is not None:
        values.append(spec.minimum if spec.exclusive_minimum else spec.minimum - 1)
    return values


BOUNDED = [
    s for s in OPTIONS if s.kind in {OptionKind.NUMBER, OptionKind.INTEGER, OptionKind.NUMBERS}
]


@pytest.mark.parametrize("spec", BOUNDED, ids=lambda s: s.key)
def test_bounds_are_the_same_on_both_front_doors(spec: OptionSpec) -> None:
    """A value beyond an option's bounds fails on the CLI (with its flag) and in the API."""
    assert _beyond(spec), spec.key
    for value in _beyond(spec):
        text = str(int(value)) if spec.kind is OptionKind.INTEGER else repr(value)
        command = ["evaluate", "r", "e"]
        build: Any = config_from_options
        if spec.group == "export":
            build = functools.partial(export_from_options, front_door="cli")
        model: type[EvaluationOptions] = EvaluationOptions
        if spec.group == "ranging":
            command = ["ranging", "r", "--anchors", "a", "--ranges", "g"]
            build, model = ranging_from_options, RangingOptions
        args = build_parser().parse_args([*command, f"{spec.flag}={text}"])
        with pytest.raises(InputError, match=rf"(?i)^{spec.words} must be") as err:
            build(args)
        assert err.value.option == spec.key
        assert describe(err.value).startswith(f"{spec.flag}: ")
        api_value: object = [value] if spec.kind is OptionKind.NUMBERS else value
        with pytest.raises(ValueError, match=spec.key):
            model.model_validate({spec.key: api_value})


def test_values_within_bounds_pass() -> None:
    """The bounds themselves (inclusive ones) are allowed by the core's check."""
    check_option("max_dt_s", 3600.0)  # the inclusive maximum (one hour)
    check_option("simplify_m", 0.0)  # the inclusive minimum: keep every vertex
    with pytest.raises(
        InputError, match=r"maximum time difference .* more than 0 and at most 3600"
    ):
        check_option("max_dt_s", 0.0, unit="seconds")


def test_each_front_door_names_the_option_its_own_way() -> None:
    """The core's error carries the key; the CLI shows the flag, the API ``options.<key>``."""
    with pytest.raises(InputError) as err:
        EvaluationConfig(max_dt_s=-1.0)
    message = str(err.value)
    assert "--" not in message
    assert message.startswith("The maximum time difference must be")
    assert describe(err.value) == f"--max-dt: {message}"
    problem = problem_for(err.value)
    assert problem["detail"] == f"options.max_dt_s: {message}"
    assert problem["option"] == "options.max_dt_s"
    plain = problem_for(InputError("No estimate given."))
    assert plain["detail"] == "No estimate given."
    assert "option" not in plain


def test_help_loads_no_heavy_library() -> None:
    """``loceval --help`` builds every parser without the web, database or plotting stack."""
    code = (
        "import json, sys\n"
        "from service.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    loaded = set(json.loads(out.splitlines()[-1]))
    assert not loaded & {"matplotlib", "fastapi", "pydantic", "sqlalchemy", "huey", "jinja2"}
