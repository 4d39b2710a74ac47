"""Rows the job tests put straight into a runtime's database: datasets and schedule runs.

The job tests (test_jobs.py, test_job_limits.py, test_job_kinds.py) drive
:mod:`service.jobs` without the HTTP API, so they store what an upload or a schedule would
have stored themselves.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from service.db import Dataset, Project, Schedule, ScheduleRun, utcnow
from service.runtime import Runtime

__all__ = ["add_dataset", "add_schedule_run"]


def add_dataset(rt: Runtime, project_id: str, path: Path) -> str:
    """Store a TUM file as a dataset row (as an upload would) and return its id.

    A file whose name is stored already is not stored again: its row's id is returned.
    """
    with rt.sessions() as session:
        existing = session.query(Dataset).filter_by(filename=path.name).first()
        if existing is not None:
            return existing.id
    target = rt.store.datasets / path.stem / path.name
    target.parent.mkdir(parents=True)
    target.write_bytes(path.read_bytes())
    with rt.sessions() as session:
        dataset = Dataset(
            project_id=project_id,
            name=path.name,
            filename=path.name,
            kind="tum",
            size_bytes=target.stat().st_size,
            sha256=path.stem.ljust(64, "0"),
            tags=[],
            inspection={"kind": "tum", "format": "tum", "sources": []},
            storage_path=str(target.relative_to(rt.store.root)),
        )
        session.add(dataset)
        session.commit()
        return dataset.id


def add_schedule_run(
    rt: Runtime,
    *,
    project_name: str,
    webhook_url: str | None = None,
    **run_columns: Any,
) -> str:
    """Record a schedule run (of a new project's weekly schedule) and return its id.

    ``run_columns`` are the run's columns besides its schedule, project and due time (now):
    ``trigger`` and ``status`` at least.
    """
    now = utcnow()
    with rt.sessions() as session:
        project = Project(name=project_name)
        session.add(project)
        session.flush()
        schedule = Schedule(
            project_id=project.id,
            name="weekly",
            cron="0 7 * * mon",
            timezone="UTC",
            selection={},
            template={},
            produce={},
            webhook_url=webhook_url,
        )
        session.add(schedule)
        session.flush()
        run = ScheduleRun(schedule_id=schedule.id, project_id=project.id, due_at=now, **run_columns)
        session.add(run)
        session.commit()
        return run.id
