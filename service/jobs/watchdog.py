"""The re-queue check of a consumer process: abandoned jobs and lost queue messages, in seconds.

Every process that consumes the queue (``loceval serve``, ``loceval worker``) runs one
:class:`Watchdog` thread. Every :func:`~service.jobs.tracking.beat_interval` (2 s by default) it
calls :func:`~service.jobs.tracking.recover`, which is cheap: one indexed query per job kind for
running jobs whose heartbeat is older than the lease. How the numbers were chosen:

* **heartbeat every 2 s, lease 10 s** (``LOCEVAL_JOB_LEASE_S``; the beat is a fifth of it).
  A beat is one small UPDATE from a thread of the worker process, whose heavy work runs in
  child processes (:mod:`service.jobs.limits`), so five beats in a row go missing only when the
  process is gone or frozen. A worker killed mid-job is noticed within lease + one check
  (12 s), and its job starts again at once on another worker.
* **a missed beat is not a dead worker when nobody could beat**: while the database is away
  no heartbeat is written, so after an outage (or when this thread itself was held up, the
  sign of a machine too busy to run its threads) the check trusts no heartbeat until the
  database has answered for a whole lease again. A job this process runs is never judged
  by its heartbeat (:func:`~service.jobs.tracking.recover` skips it).
* **lost queue messages**: the queue holds only job ids; the rows are the truth. A Redis
  without persistence that restarts comes back empty: the check reads Redis's ``run_id``
  (a new one at every start) and, when it changed or Redis or the database failed since
  the last look, compares the ``queued`` rows with what the queue holds and enqueues the
  missing ones (the claim makes a duplicate harmless). Rows queued in the last 2 s are left
  to their message on its way, so after a fault the check looks once more 2 s later: a job
  queued just before the restart is found then, not at the next 30 s look. Listing the
  queue is the expensive part, so otherwise it is done every 30 s, for rows queued for
  longer than that.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Final

from huey import RedisHuey

from service.adapters import DATABASE_ERRORS, QUEUE_ERRORS
from service.jobs.tracking import beat_interval, recover
from service.runtime import Runtime

__all__ = ["LOST_CHECK_S", "Watchdog", "start_watchdog"]

logger = logging.getLogger(__name__)

LOST_CHECK_S: Final = 30.0
"""How often the queue is compared with the queued rows when nothing went wrong."""
_FRESH_S: Final = 2.0
"""After a fault, rows queued less than this ago are left alone (their message is on its way)."""
_STALLED: Final = 3
"""A check this many periods late means this process was held up (its beats may have been)."""


class Watchdog:
    """A thread that runs :func:`~service.jobs.tracking.recover` every few seconds."""

    def __init__(self, runtime: Runtime) -> None:
        """Watch the jobs of ``runtime``'s database and queue (start it with :meth:`start`)."""
        self.runtime = runtime
        self.interval = beat_interval(runtime.settings.job_lease_s)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="loceval-watchdog", daemon=True)
        now = time.monotonic()
        self._trusted_since = now - runtime.settings.job_lease_s  # no outage seen before start
        self._last_check = now
        self._last_lost_check = now
        self._run_id: str | None = None
        self._fault = False
        self._settle_at: float | None = None
        """After a fault: look for lost messages until a look at or after this (monotonic)."""
        self._failing = False

    def start(self) -> None:
        """Start checking."""
        self._thread.start()

    def stop(self) -> None:
        """Stop checking (waits for a check under way)."""
        self._stop.set()
        self._thread.join(timeout=10)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self.check()

    def check(self) -> list[str]:
        """Run one check; return the ids queued again (an outage is logged, not raised)."""
        now = time.monotonic()
        if now - self._last_check > _STALLED * self.interval:
            self._trusted_since = now  # held up: beats of this machine may have been too
        self._last_check = now
        fault = self._queue_restarted() or self._fault
        settling = fault or self._settle_at is not None
        look = settling or now - self._last_lost_check >= LOST_CHECK_S
        lost_after = _FRESH_S if settling else LOST_CHECK_S
        try:
            requeued = recover(
                self.runtime,
                stale=now - self._trusted_since >= self.runtime.settings.job_lease_s,
                lost_after_s=lost_after if look else None,
            )
        except DATABASE_ERRORS as err:
            self._trusted_since = time.monotonic()
            self._outage("the database", err)
            return []
        except QUEUE_ERRORS as err:
            self._outage("the queue", err)
            return []
        if look:
            self._last_lost_check, self._fault = now, False
            # A row queued less than _FRESH_S before the fault was left alone by this look;
            # the next look after _FRESH_S covers it (its message was lost as well).
            if fault:
                self._settle_at = now + _FRESH_S
            elif self._settle_at is not None and now >= self._settle_at:
                self._settle_at = None
        if self._failing:
            logger.warning("Watchdog: the database and the queue answer again")
            self._failing = False
        if requeued:
            logger.warning("Watchdog: queued %d jobs again", len(requeued))
        return requeued

    def _queue_restarted(self) -> bool:
        """Return whether Redis restarted since the last look (a new ``run_id``)."""
        huey = self.runtime.huey
        if not isinstance(huey, RedisHuey):
            return False
        try:
            run_id = str(huey.storage.conn.info("server")["run_id"])
        except QUEUE_ERRORS as err:
            self._outage("the queue", err)
            return False
        restarted = self._run_id is not None and run_id != self._run_id
        if restarted:
            logger.warning("Watchdog: Redis restarted (new run_id); looking for lost jobs")
        self._run_id = run_id
        return restarted

    def _outage(self, what: str, err: Exception) -> None:
        self._fault = True
        if not self._failing:
            logger.warning("Watchdog: %s cannot be reached (%s)", what, type(err).__name__)
            self._failing = True


def start_watchdog(runtime: Runtime) -> Watchdog:
    """Start a watchdog for ``runtime`` and return it (stop it with :meth:`Watchdog.stop`)."""
    watchdog = Watchdog(runtime)
    watchdog.start()
    return watchdog
