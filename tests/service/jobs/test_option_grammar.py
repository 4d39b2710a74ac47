"""One grammar per option: the CLI, the API and a stored request give the same answer.

For every option with a grammar (the text options the table gives a pattern, and the
solvers), each value is tried at the three places an option is judged: ``loceval evaluate``
(or ``loceval ranging``), ``POST /api/v1/evaluations`` (``/ranging``), and a stored request
read for its job (:func:`service.jobs.executor._job_for`, the same check a queued job runs).
They must take the same values, and refuse the others with the same message (each door
names the option its own way: ``--tolerance:`` and ``options.tolerance:``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from loceval.errors import LocevalError
from loceval.options import OPTIONS, OptionKind, option
from service.cli import main
from service.db import Evaluation, utcnow
from service.errors import problem_for
from service.jobs.executor import _job_for
from service.jobs.kinds import RANGING, TRAJECTORY
from service.jobs.options import TEXT_PARSERS
from tests.factories import make_trajectory, perturb, write_tum
from tests.radio_factory import (
    make_anchors,
    make_ranges,
    make_reference,
    write_anchors_csv,
    write_ranges_csv,
)
from tests.service._api_fixtures import Api, open_api


@dataclass(frozen=True)
class Case:
    """One option value, as each front door spells it."""

    key: str
    cli: str
    api: Any
    accepted: bool

    @property
    def ranging(self) -> bool:
        return option(self.key).group == "ranging"

    @property
    def text(self) -> bool:
        """A text option: one parser judges it, so every door gives its message."""
        return option(self.key).kind is OptionKind.TEXT


CASES = [
    Case("tolerance", "0.10@95", "0.10@95", accepted=True),
    Case("tolerance", " 0.1 m @ 95 % ", " 0.1 m @ 95 % ", accepted=True),
    Case("tolerance", "1e-1@95", "1e-1@95", accepted=False),  # the CLI took it before
    Case("tolerance", "0.1@200", "0.1@200", accepted=False),
    Case("tolerance", "abc", "abc", accepted=False),
    Case("offset", "0 0 0.1", "0 0 0.1", accepted=True),
    Case("offset", "0,0,0.1,0,0,0,1", "0,0,0.1,0,0,0,1", accepted=True),
    Case("offset", "1e2 0 0", "1e2 0 0", accepted=False),
    Case("offset", "1 2", "1 2", accepted=False),
    Case("offset", "0 0 1001", "0 0 1001", accepted=False),
    Case("align_first", "100", "100", accepted=True),
    Case("align_first", "10s", "10s", accepted=True),
    Case("align_first", "1e1s", "1e1s", accepted=False),
    Case("align_first", "ten", "ten", accepted=False),
    Case("site", "100 200 0 90", "100 200 0 90", accepted=True),
    Case("site", "1_000 0 0", "1_000 0 0", accepted=False),
    Case("site", "0 0 0 1e300", "0 0 0 1e300", accepted=False),
    Case("crs", "EPSG:25832", "EPSG:25832", accepted=True),
    Case("crs", "25832", "25832", accepted=False),
    Case("tag_offset_xyz", "0 0 0.3", "0 0 0.3", accepted=True),
    Case("tag_offset_xyz", "\u0661 0 0", "\u0661 0 0", accepted=False),  # an Arabic-Indic 1
    Case("tag_offset_xyz", "1 2", "1 2", accepted=False),
    Case("solve", "nlls,minmax", ["nlls", "minmax"], accepted=True),
    Case("solve", "minmax", ["minmax"], accepted=True),
    Case("solve", "trilateration", ["trilateration"], accepted=False),
    # the gate's conditions: a word that is none, and conditions without the tolerance and
    # the baseline they judge (a gate that could never close), refused alike
    Case("fail_on", "failed", ["failed"], accepted=False),
    Case("fail_on", "fail,worse", ["fail", "worse"], accepted=False),
]
"""Values of every option with a grammar; ``accepted`` is the answer all three give."""


@dataclass(frozen=True)
class Answer:
    """What a front door said: taken, or refused with a message (the option's name cut)."""

    accepted: bool
    message: str = ""


def test_every_option_with_a_grammar_is_in_the_table() -> None:
    """A text option with a pattern, or a list with choices, has cases here."""
    with_grammar = {s.key for s in OPTIONS if s.pattern is not None} | {
        s.key for s in OPTIONS if s.kind is OptionKind.NAMES and s.choices and s.cli and s.api
    }
    assert with_grammar == {case.key for case in CASES}
    assert {s.key for s in OPTIONS if s.pattern is not None} == set(TEXT_PARSERS)


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Api, dict[str, str]]]:
    """An API whose queue keeps jobs waiting, with a trajectory pair and radio uploads."""
    folder = tmp_path_factory.mktemp("grammar")
    rng = np.random.default_rng(20240601)
    truth = make_trajectory(rng, n=200)
    files = {
        "reference": write_tum(folder / "gt.txt", truth),
        "estimate": write_tum(folder / "est.txt", perturb(truth, rng)),
        "walk": write_tum(folder / "walk.txt", make_reference()),
        "anchors": write_anchors_csv(folder / "anchors.csv", make_anchors()),
        "ranges": write_ranges_csv(folder / "ranges.csv", make_ranges(rng).ranges),
    }
    with open_api(folder, queue_url="sqlite") as api:
        ids = {
            role: api.dataset(path.name, path.read_bytes())["id"] for role, path in files.items()
        }
        yield api, ids


def _cli(case: Case, folder: Path, capsys: pytest.CaptureFixture[str]) -> Answer:
    """Run the command with inputs that do not exist: an option is judged before they are read."""
    spec = option(case.key)
    missing = folder / "missing.txt"
    if case.ranging:
        argv = ["ranging", str(missing), "--anchors", str(missing), "--ranges", str(missing)]
    else:
        argv = ["evaluate", str(missing), str(missing), "--out", str(folder / "out")]
    code = main([*argv, f"{spec.flag}={case.cli}"])
    err = capsys.readouterr().err.strip()
    assert code == 1, err  # taken: the missing input is the error; refused: the option
    prefix = f"loceval: error: {spec.flag}: "
    if not err.startswith(prefix):
        assert "missing.txt" in err, err
        return Answer(accepted=True)
    return Answer(accepted=False, message=err.removeprefix(prefix))


def _body(case: Case, ids: dict[str, str]) -> tuple[str, dict[str, Any]]:
    if case.ranging:
        return "/api/v1/ranging", {
            "reference": {"dataset_id": ids["walk"]},
            "anchors": ids["anchors"],
            "ranges": {"dataset_id": ids["ranges"]},
            "options": {case.key: case.api, "formats": ["result.json"]},
        }
    return "/api/v1/evaluations", {
        "reference": {"dataset_id": ids["reference"]},
        "estimates": [{"dataset_id": ids["estimate"]}],
        "options": {case.key: case.api, "formats": ["result.json"]},
    }


def _api(case: Case, api: Api, ids: dict[str, str]) -> Answer:
    path, body = _body(case, ids)
    answer = api.client.post(path, headers=api.headers, json=body)
    if answer.status_code == 202:
        return Answer(accepted=True)
    assert answer.status_code == 422, answer.text
    detail = str(answer.json()["detail"])
    return Answer(accepted=False, message=detail.removeprefix(f"options.{case.key}: "))


def _stored(case: Case, api: Api, ids: dict[str, str]) -> Answer:
    """Store the request as it would have been stored, then read it for its job."""
    _, body = _body(case, ids)
    request = dict(body)
    kind = RANGING if case.ranging else TRAJECTORY
    if case.ranging:
        request["estimates"] = [{"dataset_id": ids["ranges"], "selector": None, "name": "nlls"}]
    runtime = api.app.state.runtime
    with runtime.sessions() as session:
        row = Evaluation(
            project_id=api.project_id(),
            kind=kind,
            request=request,
            dataset_ids=sorted(ids.values()),
            created_at=utcnow(),
        )
        session.add(row)
        session.commit()
        try:
            _job_for(session, runtime, row)
        except LocevalError as err:
            detail = problem_for(err)["detail"]
            return Answer(accepted=False, message=detail.removeprefix(f"options.{case.key}: "))
        except ValueError as err:  # the stored request no longer fits its model (pydantic)
            return Answer(accepted=False, message=str(err))
    return Answer(accepted=True)


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c.key}={c.cli}")
def test_the_same_answer_at_every_front_door(
    case: Case,
    world: tuple[Api, dict[str, str]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The CLI, the API and a stored request take or refuse the value alike, with one message."""
    api, ids = world
    cli, http, stored = _cli(case, tmp_path, capsys), _api(case, api, ids), _stored(case, api, ids)
    assert (cli.accepted, http.accepted, stored.accepted) == (case.accepted,) * 3
    if case.text:
        assert cli.message == http.message == stored.message
