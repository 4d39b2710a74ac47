"""Lists page in SQL (LIMIT/OFFSET, a COUNT for the total) and never load result documents."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event, update

from service.db import Evaluation
from tests.service._api_fixtures import Api, open_api

_TUM = b"0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n2 2 0 0 0 0 0 1\n"


@contextmanager
def _statements(api: Api) -> Iterator[list[str]]:
    """Collect the SQL the app sends while the block runs."""
    seen: list[str] = []
    engine = api.app.state.runtime.engine

    def record(*args: Any) -> None:
        seen.append(str(args[2]))

    event.listen(engine, "before_cursor_execute", record)
    try:
        yield seen
    finally:
        event.remove(engine, "before_cursor_execute", record)


def _evaluations(api: Api, dataset_id: str, n: int) -> list[str]:
    """Insert ``n`` evaluations with a result document, one second apart; return their ids."""
    ids = [api.insert_evaluation([dataset_id], status="succeeded") for _ in range(n)]
    start = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    with api.app.state.runtime.sessions() as session:
        for k, evaluation_id in enumerate(ids):
            session.execute(
                update(Evaluation)
                .where(Evaluation.id == evaluation_id)
                .values(created_at=start + dt.timedelta(seconds=k), result={"big": "x" * 1000})
            )
        session.commit()
    return ids


def test_evaluations_page_in_sql_without_results(tmp_path: Path) -> None:
    """?limit=2&offset=1 returns the 2nd and 3rd newest, the total, and no result column."""
    with open_api(tmp_path) as api:
        dataset = api.dataset("gt.txt", _TUM)
        ids = _evaluations(api, dataset["id"], 5)
        with _statements(api) as sql:
            page = api.client.get("/api/v1/evaluations?limit=2&offset=1", headers=api.headers)
    assert page.status_code == 200, page.text
    assert page.json()["count"] == 5
    assert [e["id"] for e in page.json()["items"]] == [ids[3], ids[2]]  # newest first
    assert all(e["result"] is None for e in page.json()["items"])
    (listing,) = [s for s in sql if "FROM evaluations" in s and "count(" not in s]
    assert "LIMIT" in listing
    assert "OFFSET" in listing
    assert "evaluations.result" not in listing
    assert any("count(" in s and "FROM evaluations" in s for s in sql)


def test_the_status_filter_counts_in_sql(tmp_path: Path) -> None:
    """The total of a filtered list counts the filtered rows only."""
    with open_api(tmp_path) as api:
        dataset = api.dataset("gt.txt", _TUM)
        _evaluations(api, dataset["id"], 3)
        queued = api.insert_evaluation([dataset["id"]])
        page = api.client.get("/api/v1/evaluations?status=queued", headers=api.headers).json()
    assert page["count"] == 1
    assert [e["id"] for e in page["items"]] == [queued]


@pytest.mark.parametrize("database", ["sqlite", "postgresql"])
def test_datasets_filter_by_tag_and_page_in_sql(
    tmp_path: Path, database: str, request: pytest.FixtureRequest
) -> None:
    """?tag= matches whole tags in SQL (SQLite and PostgreSQL); the total counts those only."""
    url = "" if database == "sqlite" else request.getfixturevalue("postgres_url")
    with open_api(tmp_path, database_url=url) as api:
        tagged = [
            api.dataset(f"run{k}.txt", _TUM + f"3 {k} 0 0 0 0 0 1\n".encode(), tags=tags)
            for k, tags in enumerate(["level2, amcl", "level2", "level20", "level3"])
        ]
        with _statements(api) as sql:
            page = api.client.get("/api/v1/datasets?tag=level2&limit=1", headers=api.headers).json()
        rest = api.client.get(
            "/api/v1/datasets?tag=level2&limit=1&offset=1", headers=api.headers
        ).json()
    assert page["count"] == 2  # "level20" is another tag
    assert [d["id"] for d in page["items"] + rest["items"]] == [tagged[1]["id"], tagged[0]["id"]]
    (listing,) = [s for s in sql if "FROM datasets" in s and "count(" not in s]
    assert "LIMIT" in listing
    assert ("json_each" if database == "sqlite" else "@>") in listing


def test_datasets_by_sha256(tmp_path: Path) -> None:
    """?sha256= finds the project's dataset of those bytes (any case), else none; bad: 422."""
    import hashlib

    other = _TUM + b"3 3 0 0 0 0 0 1\n"
    with open_api(tmp_path) as api:
        held = api.dataset("gt.txt", _TUM)
        api.dataset("other.txt", other)
        digest = hashlib.sha256(_TUM).hexdigest()
        found = api.client.get(f"/api/v1/datasets?sha256={digest.upper()}", headers=api.headers)
        missing = api.client.get(
            f"/api/v1/datasets?sha256={hashlib.sha256(b'x').hexdigest()}", headers=api.headers
        )
        bad = api.client.get("/api/v1/datasets?sha256=abc", headers=api.headers)
    assert found.status_code == 200, found.text
    assert found.json()["count"] == 1
    assert [d["id"] for d in found.json()["items"]] == [held["id"]]
    assert found.json()["items"][0]["sha256"] == digest
    assert missing.json() == {"items": [], "count": 0}
    assert bad.status_code == 422
