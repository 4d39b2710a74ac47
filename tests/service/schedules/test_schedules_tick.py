"""Schedules fire from the queue's tick: once per due time, never while paused, late once.

The clock is frozen: :func:`service.schedules.resource.tick` takes ``now``, and the tests walk it
minute by minute. Two real processes ticking the same database stand for two consumers.
"""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from sqlalchemy import select

from loceval.errors import InputError
from service.db import Dataset, Project, Schedule, ScheduleRun
from service.jobs.queue import create_runtime
from service.runtime import Runtime
from service.schedules.resource import check_cron, next_fire, select_datasets, tick
from service.settings import Settings

T0 = dt.datetime(2026, 11, 23, 6, 59, 30, tzinfo=dt.UTC)


@pytest.fixture
def runtime(tmp_path: Path):
    """A runtime with huey's SQLite queue and no consumer: fired runs wait in the queue."""
    rt = create_runtime(Settings(data_dir=tmp_path / "data"))
    yield rt
    rt.close()


def _schedule(rt: Runtime, *, cron: str = "* * * * *", tz: str = "UTC", paused: bool = False):
    with rt.sessions() as session:
        project = Project(name="site")
        session.add(project)
        session.flush()
        schedule = Schedule(
            project_id=project.id,
            name="weekly",
            cron=cron,
            timezone=tz,
            paused=paused,
            selection={},
            template={"reference": {"selector": "/gt"}, "estimates": [{"selector": "/est"}]},
            produce={},
            next_fire_at=next_fire(cron, tz, T0),
            created_at=T0,
            updated_at=T0,
        )
        session.add(schedule)
        session.commit()
        return schedule


def _runs(rt: Runtime) -> list[ScheduleRun]:
    with rt.sessions() as session:
        return list(session.scalars(select(ScheduleRun).order_by(ScheduleRun.due_at)))


def test_a_minutely_schedule_fires_once_per_due_minute(runtime: Runtime):
    """Ticking every 20 s for five minutes gives five runs, one per minute, in order."""
    _schedule(runtime)
    for k in range(15):
        tick(runtime, T0 + dt.timedelta(seconds=20 * k + 31))
    runs = _runs(runtime)
    minutes = [T0.replace(second=0) + dt.timedelta(minutes=m) for m in range(1, 6)]
    assert [r.due_at for r in runs] == minutes
    assert {r.trigger for r in runs} == {"cron"}
    assert runtime.huey.pending_count() == 5


def test_a_paused_schedule_does_not_fire(runtime: Runtime):
    """Paused schedules are skipped by the tick."""
    _schedule(runtime, paused=True)
    for m in range(5):
        tick(runtime, T0 + dt.timedelta(minutes=m + 1))
    assert _runs(runtime) == []


def test_a_missed_fire_runs_once_late_and_says_so(runtime: Runtime):
    """Down for three days: one run at start, marked missed, counting what it stands for."""
    schedule = _schedule(runtime, cron="0 7 * * *", tz="Europe/Berlin")
    assert schedule.next_fire_at == dt.datetime(2026, 11, 24, 6, 0, tzinfo=dt.UTC)
    start = dt.datetime(2026, 11, 27, 9, 12, tzinfo=dt.UTC)
    fired = tick(runtime, start)
    assert len(fired) == 1
    (run,) = _runs(runtime)
    assert run.trigger == "missed"
    assert run.due_at == dt.datetime(2026, 11, 24, 6, 0, tzinfo=dt.UTC)
    assert run.note is not None
    assert "not running at 2026-11-24 06:00 UTC" in run.note
    assert "stands for 4 missed fires" in run.note
    assert tick(runtime, start + dt.timedelta(seconds=30)) == []
    with runtime.sessions() as session:
        assert session.get_one(Schedule, schedule.id).next_fire_at == dt.datetime(
            2026, 11, 28, 6, 0, tzinfo=dt.UTC
        )


def test_cron_follows_the_time_zone_across_daylight_saving():
    """07:00 in Berlin is 05:00 UTC in summer and 06:00 UTC in winter."""
    summer = next_fire("0 7 * * *", "Europe/Berlin", dt.datetime(2026, 7, 1, tzinfo=dt.UTC))
    winter = next_fire("0 7 * * *", "Europe/Berlin", dt.datetime(2026, 12, 1, tzinfo=dt.UTC))
    assert (summer.hour, winter.hour) == (5, 6)


@pytest.mark.parametrize(
    ("cron", "tz", "match"),
    [
        ("61 * * * *", "UTC", "Invalid cron expression '61 \\* \\* \\* \\*'"),
        ("every monday", "UTC", "five fields"),
        ("* * * * * *", "UTC", "five fields"),
        ("0 7 * * mon", "Mars/Olympus", "Unknown time zone 'Mars/Olympus'"),
        ("0 7 * * mon", "", "Unknown time zone"),
    ],
)
def test_bad_cron_or_zone(cron: str, tz: str, match: str):
    """Invalid cron expressions and unknown zones are input errors that say what to write."""
    with pytest.raises(InputError, match=match):
        check_cron(cron, tz)


def test_two_processes_ticking_fire_each_minute_once(runtime: Runtime, tmp_path: Path):
    """Two consumer processes ticking the same minutes at once record each due time once."""
    _schedule(runtime)
    runtime.close()
    code = textwrap.dedent(
        f"""
        import datetime as dt, json, sys, time
        from service.jobs.queue import create_runtime
        from service.schedules.resource import tick
        from service.settings import Settings
        rt = create_runtime(Settings(data_dir={str(tmp_path / "data")!r}))
        t0 = dt.datetime.fromisoformat({T0.isoformat()!r})
        start = float(sys.argv[1])
        while time.time() < start:
            time.sleep(0.001)
        fired = []
        for k in range(40):  # every 15 s for 10 minutes, on a frozen clock
            fired += tick(rt, t0 + dt.timedelta(seconds=15 * k + 31))
        print(json.dumps(fired))
        """
    )
    start = f"{time.time() + 3:.3f}"
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code, start], stdout=subprocess.PIPE, text=True, cwd="."
        )
        for _ in range(2)
    ]
    outputs = [p.communicate(timeout=120)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0]
    fired = [json.loads(o) for o in outputs]
    check = create_runtime(Settings(data_dir=tmp_path / "data"))
    try:
        runs = _runs(check)
    finally:
        check.close()
    due = [r.due_at for r in runs]
    assert len(due) == len(set(due)) == 10
    assert due == [T0.replace(second=0) + dt.timedelta(minutes=m) for m in range(1, 11)]
    assert sorted(fired[0] + fired[1]) == sorted(r.id for r in runs)


def _dataset(name: str, tags: list[str], created: dt.datetime, fmt: str = "bag") -> Dataset:
    return Dataset(
        id=name,
        project_id="p",
        name=name,
        filename=f"{name}.bag",
        kind="rosbag1",
        size_bytes=1,
        sha256=name,
        tags=tags,
        inspection={"format": fmt},
        storage_path="x",
        created_at=created,
    )


def test_selection_by_tags_name_and_age():
    """Tags must all be present, the pattern matches name or file, the age counts back."""
    now = dt.datetime(2026, 11, 23, 7, tzinfo=dt.UTC)
    datasets = [
        _dataset("level2-run1", ["level2", "amcl"], now - dt.timedelta(days=2)),
        _dataset("level2-run2", ["level2"], now - dt.timedelta(days=9)),
        _dataset("level3-run1", ["level3", "amcl"], now - dt.timedelta(days=1)),
        _dataset("later", ["level2", "amcl"], now + dt.timedelta(minutes=1)),
        _dataset("robot", ["level2", "amcl"], now - dt.timedelta(days=1), fmt="urdf"),
    ]

    def names(selection: dict[str, object]) -> list[str]:
        return [d.name for d in select_datasets(datasets, selection, as_of=now)]

    assert names({}) == ["level2-run2", "level2-run1", "level3-run1"]
    assert names({"tags": ["level2", "amcl"]}) == ["level2-run1"]
    assert names({"name_pattern": "LEVEL2-*"}) == ["level2-run2", "level2-run1"]
    assert names({"uploaded_within_days": 7}) == ["level2-run1", "level3-run1"]
    assert names({"tags": ["nothing"]}) == []
