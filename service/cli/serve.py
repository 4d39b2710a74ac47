"""``loceval serve``, ``worker`` and ``keys``: the service's commands.

Each imports the service (FastAPI, SQLAlchemy, huey) only when it runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from loceval import __version__
from loceval.errors import InputError

if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable

    from service.runtime import Runtime
    from service.settings import Settings

__all__ = ["run_keys_create", "run_keys_revoke", "run_serve", "run_worker"]


def run_serve(args: argparse.Namespace) -> int:
    """Start the HTTP service (with its queue consumer unless told not to)."""
    from service.api.http_server import run  # noqa: PLC0415
    from service.auth import bootstrap  # noqa: PLC0415
    from service.jobs.queue import create_runtime  # noqa: PLC0415
    from service.main import create_app  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    settings = _settings(get_settings)
    host: str = args.host if args.host is not None else settings.host
    port: int = args.port if args.port is not None else settings.port
    # links follow the address served on, unless LOCEVAL_PUBLIC_URL says otherwise
    settings = settings.model_copy(update={"host": host, "port": port})
    runtime = _open_runtime(create_runtime, settings)
    with runtime.sessions() as session:
        key = bootstrap(session)
    if key is not None:
        print(f"API key for project 'default' (shown once): {key}", flush=True)  # noqa: T201
    app = create_app(settings, runtime=runtime, consumer=not args.no_consumer)
    print(  # noqa: T201
        f"loceval {__version__}: http://{host}:{port}/ (data in "
        f"{settings.data_dir.resolve()}, {_blobs(runtime)}queue {settings.queue_url}; "
        f"links start with {settings.resolved_public_url.rstrip('/')}/, "
        "set by LOCEVAL_PUBLIC_URL)",
        flush=True,
    )
    try:
        run(app, host=host, port=port)
    finally:
        runtime.close()  # a bucket's upload lease is deleted, the data folder's lock let go
    return 0


def run_worker(_args: argparse.Namespace) -> int:
    """Run queue consumers until SIGINT or SIGTERM."""
    import signal  # noqa: PLC0415
    import sys  # noqa: PLC0415
    import threading  # noqa: PLC0415

    from service.jobs.queue import create_runtime  # noqa: PLC0415
    from service.jobs.tracking import recover  # noqa: PLC0415
    from service.logs import configure_logging  # noqa: PLC0415
    from service.preflight import check_data_dir  # noqa: PLC0415
    from service.schedules.resource import tick  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    configure_logging()  # once, for the consumer threads and the jobs' processes alike
    settings = _settings(get_settings)
    runtime = _open_runtime(create_runtime, settings)
    if settings.queue_url == "immediate":
        msg = "LOCEVAL_QUEUE_URL=immediate runs jobs inside requests; a worker needs a queue."
        raise InputError(msg)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    low_space = check_data_dir(settings)  # create_runtime refused an unwritable one already
    if low_space:
        print(f"loceval: warning: {low_space}", file=sys.stderr, flush=True)  # noqa: T201
    consumer = runtime.start_consumer()
    recover(runtime)
    tick(runtime)
    print(  # noqa: T201
        f"loceval worker: {settings.workers} threads on queue {settings.queue_url}"
        f"{'; ' + runtime.store.description if runtime.store.kind != 'local' else ''}",
        flush=True,
    )
    stop.wait()
    runtime.stop_consumer(consumer)
    runtime.close()
    return 0


def run_keys_create(args: argparse.Namespace) -> int:
    """Create an API key and print it."""
    from service.auth import create_key  # noqa: PLC0415
    from service.jobs.queue import create_runtime  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    runtime = _open_runtime(create_runtime, _settings(get_settings))
    with runtime.sessions() as session:
        print(create_key(session, args.project))  # noqa: T201
    runtime.close()
    return 0


def run_keys_revoke(args: argparse.Namespace) -> int:
    """Revoke an API key."""
    from service.auth import revoke_key  # noqa: PLC0415
    from service.jobs.queue import create_runtime  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    runtime = _open_runtime(create_runtime, _settings(get_settings))
    with runtime.sessions() as session:
        revoke_key(session, args.key)
    runtime.close()
    print("Key revoked.")  # noqa: T201
    return 0


def _settings(get: Callable[[], Settings]) -> Settings:
    from pydantic import ValidationError  # noqa: PLC0415

    try:
        return get()
    except ValidationError as err:
        problems = "; ".join(
            f"LOCEVAL_{'_'.join(str(p) for p in e['loc']).upper()}: {e['msg']}"
            for e in err.errors()
        )
        msg = f"Bad service settings: {problems}."
        raise InputError(msg) from None


def _open_runtime(create: Callable[[Settings], Runtime], settings: Settings) -> Runtime:
    from sqlalchemy.exc import SQLAlchemyError  # noqa: PLC0415

    try:
        return create(settings)
    except SQLAlchemyError as err:
        msg = (
            f"Cannot open the database {settings.resolved_database_url!r} "
            f"({type(err).__name__}: {str(err).splitlines()[0]}); check LOCEVAL_DATABASE_URL."
        )
        raise InputError(msg) from err
    except OSError as err:
        msg = (
            f"Cannot use the data directory {str(settings.data_dir)!r} ({err.strerror}); "
            "check LOCEVAL_DATA_DIR."
        )
        raise InputError(msg) from err


def _blobs(runtime: Runtime) -> str:
    """Return where the blobs are for the start line, when not in the data folder."""
    return "" if runtime.store.kind == "local" else f"{runtime.store.description}, "
