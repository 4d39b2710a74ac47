"""``loceval keys``, ``serve`` and ``worker``: settings and key management from the shell."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.auth import authenticate
from service.cli import main
from service.jobs.queue import create_runtime
from service.settings import Settings, get_settings


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch) -> Path:
    """Point LOCEVAL_DATA_DIR at a temporary folder and reset the cached settings."""
    monkeypatch.setenv("LOCEVAL_DATA_DIR", str(tmp_path))
    get_settings.cache_clear()
    yield tmp_path
    get_settings.cache_clear()


def _project_of(data_dir: Path, key: str) -> str | None:
    runtime = create_runtime(Settings(data_dir=data_dir))
    try:
        with runtime.sessions() as session:
            return authenticate(session, key)
    finally:
        runtime.close()


def test_keys_create_prints_only_a_working_key(data_dir: Path, capsys):
    """The key is the only output, so scripts can capture it; it authenticates."""
    assert main(["keys", "create", "--project", "site-a"]) == 0
    key = capsys.readouterr().out.strip()
    assert key.startswith("lcv_")
    assert len(key.splitlines()) == 1
    assert _project_of(data_dir, key) is not None


def test_keys_of_one_project_share_it(data_dir: Path, capsys):
    """Two keys for the same project name open the same project; another name another."""
    for name in ("site-a", "site-a", "site-b"):
        main(["keys", "create", "--project", name])
    a1, a2, b = capsys.readouterr().out.split()
    assert _project_of(data_dir, a1) == _project_of(data_dir, a2) != _project_of(data_dir, b)


def test_keys_revoke_by_prefix(data_dir: Path, capsys):
    """A key revoked by its visible prefix no longer authenticates."""
    main(["keys", "create", "--project", "site-a"])
    key = capsys.readouterr().out.strip()
    assert main(["keys", "revoke", key[:12]]) == 0
    assert "revoked" in capsys.readouterr().out
    assert _project_of(data_dir, key) is None
    assert main(["keys", "revoke", key]) == 1
    assert "unknown or already revoked" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["keys", "create", "--project", "  "], "project name needs 1 to 200 characters"),
        (["keys", "revoke", "lcv"], "Give the key or its first 12 characters"),
        (["keys", "revoke", "lcv_nothing_like_it_at_all_0000000000000"], "No active key"),
    ],
)
@pytest.mark.usefixtures("data_dir")
def test_keys_bad_input_exits_1(capsys, argv: list[str], message: str):
    """Bad key commands exit 1 with a message, no traceback."""
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


@pytest.mark.usefixtures("data_dir")
def test_keys_without_a_subcommand_is_a_usage_error(capsys):
    """``loceval keys`` alone prints the usage and exits 1."""
    with pytest.raises(SystemExit) as exc:
        main(["keys"])
    assert exc.value.code == 1
    assert "required" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("variable", "value", "message"),
    [
        ("LOCEVAL_QUEUE_URL", "amqp://x", "LOCEVAL_QUEUE_URL must be sqlite, immediate or redis"),
        ("LOCEVAL_WORKERS", "0", "LOCEVAL_WORKERS"),
        ("LOCEVAL_MAX_UPLOAD_BYTES", "lots", "LOCEVAL_MAX_UPLOAD_BYTES"),
        (
            "LOCEVAL_DATABASE_URL",
            "postgresql+psycopg://nobody@127.0.0.1:1/none",
            "Cannot open the database",
        ),
    ],
)
@pytest.mark.usefixtures("data_dir")
def test_bad_settings_exit_1(monkeypatch, capsys, variable, value, message):
    """A wrong LOCEVAL_* setting stops serve with a message naming it, not a traceback."""
    monkeypatch.setenv(variable, value)
    get_settings.cache_clear()
    assert main(["serve", "--port", "1"]) == 1
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


@pytest.mark.usefixtures("data_dir")
def test_worker_refuses_the_immediate_queue(monkeypatch, capsys):
    """A worker needs a real queue; immediate mode is for tests only."""
    monkeypatch.setenv("LOCEVAL_QUEUE_URL", "immediate")
    get_settings.cache_clear()
    assert main(["worker"]) == 1
    assert "a worker needs a queue" in capsys.readouterr().err
