"""Start-up checks: the data directory (writable, free space) and the migration level."""

from __future__ import annotations

import errno
import logging
import os
from collections import namedtuple
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import text

from service import preflight
from service.cli import main
from service.jobs.queue import create_runtime
from service.main import create_app
from service.preflight import StartupError, check_data_dir, schema_heads
from service.settings import Settings, get_settings

_Usage = namedtuple("_Usage", ["total", "used", "free"])  # noqa: PYI024  (shutil's shape)


def settings_for(data_dir: Path, **values: object) -> Settings:
    """Return settings on ``data_dir`` with the immediate queue."""
    return Settings(data_dir=data_dir, queue_url="immediate", **values)  # type: ignore[arg-type]


@pytest.fixture
def env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """Point the CLI's settings at a data folder (returned); the cached settings are reset."""
    data_dir = tmp_path / "data"
    for name in list(os.environ):
        if name.startswith("LOCEVAL_"):
            monkeypatch.delenv(name)
    monkeypatch.setenv("LOCEVAL_DATA_DIR", str(data_dir))
    monkeypatch.setenv("LOCEVAL_QUEUE_URL", "immediate")
    get_settings.cache_clear()
    yield data_dir
    get_settings.cache_clear()


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    """Run the CLI; return its exit code and stderr."""
    code = main(list(argv))
    return code, capsys.readouterr().err


# --- the data directory --------------------------------------------------------------------


def test_data_dir_is_created(tmp_path: Path) -> None:
    """A missing data directory is created; no probe file is left in it."""
    folder = tmp_path / "new" / "data"
    assert check_data_dir(settings_for(folder)) is None
    assert folder.is_dir()
    assert list(folder.iterdir()) == []


def test_data_dir_that_cannot_be_created(env: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A file where the folder should be: exit 1 saying what to do, no traceback."""
    env.write_text("not a folder")
    code, err = run_cli(capsys, "keys", "create", "--project", "site")
    assert code == 1
    assert "The data directory" in err
    assert "cannot be created" in err
    assert "LOCEVAL_DATA_DIR" in err
    assert "Traceback" not in err


def test_read_only_data_dir_is_refused(
    env: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The probe write fails (a read-only volume): exit 1 naming the cause and the fix."""
    env.mkdir()

    def read_only(_folder: Path) -> None:
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(preflight, "_probe_write", read_only)
    code, err = run_cli(capsys, "worker")
    assert code == 1
    assert "is not writable (Read-only file system)" in err
    assert "give the user running loceval write access" in err
    assert "Traceback" not in err
    assert not (env / "loceval.db").exists()  # refused before the database was opened


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_unwritable_data_dir_is_refused(tmp_path: Path) -> None:
    """A real folder without write permission is refused by the probe."""
    folder = tmp_path / "data"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(StartupError, match="is not writable"):
            check_data_dir(settings_for(folder))
    finally:
        folder.chmod(0o700)


def test_app_start_checks_the_data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """create_app on an unwritable folder raises the same clear error."""

    def read_only(_folder: Path) -> None:
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr(preflight, "_probe_write", read_only)
    with pytest.raises(StartupError, match="Permission denied"):
        create_app(settings_for(tmp_path / "data"))


def test_low_space_is_a_warning(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Less free space than the reserve: a warning naming the setting; the service starts."""
    monkeypatch.setattr(
        "service.preflight.shutil.disk_usage",
        lambda _p: _Usage(10**12, 10**12 - 300 * 10**6, 300 * 10**6),
    )
    settings = settings_for(tmp_path / "data", min_free_bytes=2 * 10**9)
    warning = check_data_dir(settings)
    assert warning is not None
    assert "has 300 MB free, less than the 2.0 GB" in warning
    assert "LOCEVAL_MIN_FREE_BYTES" in warning
    assert "uploads are refused (507)" in warning
    runtime = create_runtime(settings)  # not refused
    runtime.close()
    assert check_data_dir(settings_for(tmp_path / "data", min_free_bytes=10**8)) is None


@pytest.mark.usefixtures("env")
def test_worker_prints_the_low_space_warning(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``loceval worker`` says it on stderr before it starts consuming."""
    monkeypatch.setattr(
        "service.preflight.shutil.disk_usage", lambda _p: _Usage(10**12, 10**12, 5 * 10**6)
    )
    monkeypatch.setenv("LOCEVAL_QUEUE_URL", "sqlite")

    class Stop(Exception):  # noqa: N818  (ends the test once the warning is out)
        """Raised instead of starting the consumer."""

    def no_consumer(*_args: object, **_kwargs: object) -> None:
        raise Stop

    monkeypatch.setattr("service.runtime.Runtime.start_consumer", no_consumer)
    monkeypatch.setattr("signal.signal", lambda *_args: None)  # keep pytest's handlers
    with pytest.raises(Stop):
        _run_worker()
    err = capsys.readouterr().err
    assert "loceval: warning: The data directory" in err
    assert "5 MB free" in err


def _run_worker() -> int:
    """Run ``loceval worker``'s handler directly (main() would turn Stop into exit 2)."""
    import argparse

    from service.cli.serve import run_worker

    return run_worker(argparse.Namespace())


# --- the migration level --------------------------------------------------------------------


def set_revision(settings: Settings, revision: str) -> None:
    """Write a revision into the database's alembic_version table."""
    runtime = create_runtime(settings)
    try:
        with runtime.engine.begin() as connection:
            connection.execute(text("UPDATE alembic_version SET version_num = :r"), {"r": revision})
    finally:
        runtime.close()


def test_database_newer_than_the_code_is_refused(tmp_path: Path) -> None:
    """A migration this code does not know: refused, saying a newer loceval upgraded it."""
    settings = settings_for(tmp_path / "data")
    set_revision(settings, "9999")
    with pytest.raises(StartupError) as caught:
        create_runtime(settings)
    message = str(caught.value)
    assert "The database is at migration 9999" in message
    assert "a newer loceval has upgraded it" in message
    assert "LOCEVAL_DATABASE_URL" in message
    assert str(tmp_path) not in message


def test_database_newer_than_the_code_exits_1(
    env: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``loceval keys create`` on a newer database: exit 1 with the message, no traceback."""
    set_revision(settings_for(env), "9999")
    code, err = run_cli(capsys, "keys", "create", "--project", "site")
    assert code == 1
    assert "migration 9999" in err
    assert "Traceback" not in err


def test_database_behind_is_migrated(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A database one migration behind is brought up on start, with a log line."""
    settings = settings_for(tmp_path / "data")
    runtime = create_runtime(settings)
    _, head = schema_heads(runtime.engine)
    with runtime.engine.begin() as connection:
        connection.execute(text("DROP TABLE schedule_runs"))
        connection.execute(text("DROP TABLE schedules"))
        connection.execute(text("UPDATE alembic_version SET version_num = '0001'"))
    runtime.close()
    with caplog.at_level(logging.WARNING, logger="service.preflight"):
        runtime = create_runtime(settings)
    try:
        assert schema_heads(runtime.engine) == ((head,), head)
        with runtime.engine.connect() as connection:
            assert connection.execute(text("SELECT count(*) FROM schedules")).scalar() == 0
    finally:
        runtime.close()
    assert any(f"from migration 0001 to {head}" in r.getMessage() for r in caplog.records)


def test_database_behind_without_migrating_is_refused(tmp_path: Path) -> None:
    """apply_migrations=False on an older database: refused with what to run."""
    settings = settings_for(tmp_path / "data")
    set_revision(settings, "0001")
    with pytest.raises(StartupError, match="older than this loceval's"):
        create_runtime(settings, apply_migrations=False)


def test_fresh_database_is_created_quietly(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """An empty database is migrated to the head without a warning."""
    with caplog.at_level(logging.WARNING, logger="service.preflight"):
        runtime = create_runtime(settings_for(tmp_path / "data"))
    try:
        current, head = schema_heads(runtime.engine)
        assert current == (head,)
    finally:
        runtime.close()
    assert not [r for r in caplog.records if r.name == "service.preflight"]
