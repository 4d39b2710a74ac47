"""``loceval submit`` sends ``loceval evaluate``'s options as the API's options document."""

from __future__ import annotations

from typing import Any

import pytest

from loceval.errors import InputError
from service.cli.parser import build_parser
from service.cli.submit import api_options, flags_named
from service.schemas.evaluations import EvaluationOptions


def _options(*flags: str) -> dict[str, Any]:
    args = build_parser().parse_args(
        ["submit", "gt.txt", "est.txt", "--server", "http://127.0.0.1:9", *flags]
    )
    return api_options(args, held=None)  # type: ignore[arg-type]  (no file option given)


def test_given_options_go_under_their_keys_and_the_api_takes_them() -> None:
    """Only the options given are sent, in the API's types; the API's model validates them."""
    options = _options(
        "--align", "sim3", "--thresholds", "0.1,0.2", "--rpe-all-pairs", "--formats", "json",
        "--time-offset", "auto", "--tolerance", "0.10@95", "--worst", "3",
    )  # fmt: skip
    assert options == {
        "align": "sim3",
        "thresholds_m": [0.1, 0.2],
        "rpe_all_pairs": True,
        "formats": ["json"],
        "time_offset_s": "auto",
        "tolerance": "0.10@95",
        "worst": 3,
    }
    EvaluationOptions.model_validate(options)
    assert _options() == {}  # the defaults are the service's


def test_the_services_option_names_become_the_flags() -> None:
    """A refused option's line names the CLI's flag, not the API's ``options.KEY``."""
    assert flags_named("options.max_dt_s: too large") == "--max-dt: too large"
    assert flags_named("options.nothing: kept") == "options.nothing: kept"


def test_a_format_prefix_is_refused(tmp_path: Any) -> None:
    """The service recognises each file's format: submit refuses a FORMAT: prefix."""
    from service.cli.submit import run_submit

    (tmp_path / "gt.txt").write_text("0 0 0 0 0 0 0 1\n", encoding="utf-8")
    args = build_parser().parse_args(
        ["submit", f"tum:{tmp_path / 'gt.txt'}", str(tmp_path / "gt.txt"), "--server", "http://x"]
    )
    with pytest.raises(InputError, match="FORMAT: prefix"):
        run_submit(args)
