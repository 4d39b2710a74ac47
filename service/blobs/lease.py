"""Which API process an upload in the bucket belongs to, and whether that process lives.

Every process that receives uploads into a bucket has an *instance* id, and its uploads' keys
carry it (``uploads/<instance>/<uuid>``). Two facts tell a sweep that an instance is gone:

- its **lease**, the object ``instances/<instance>`` in the bucket, rewritten every
  ``lease_s / 4`` seconds by a thread of the process, is older than ``lease_s`` (judged by the
  store's own clock: the list's ``Date`` header against the objects' ``LastModified``) or
  missing. This holds across machines and containers, whatever their host names.
- its **slot** in the local data folder, ``instances/<instance>.lock``, is not held: the
  process holds the slot's ``flock`` while it lives, and the kernel drops it when the process
  dies. A process that starts on that folder takes a free slot, so its identity is the gone
  process's, and its start-up sweep aborts at once what that process left (no lease to wait
  out); a second process on the same folder finds the slot held and takes a new one.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import threading
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import IO, Final

__all__ = ["LEASE_S", "Lease", "claim_slot"]

logger = logging.getLogger(__name__)

LEASE_S: Final = 120.0
"""A lease not renewed for this long belongs to a process that is gone."""


def claim_slot(folder: Path) -> tuple[str, IO[bytes]]:
    """Take a free instance slot in ``folder`` (a gone process's, else a new one).

    Returns:
        The instance id and the open slot file, whose ``flock`` the caller keeps while it
        lives (closing the file lets the slot go).
    """
    folder.mkdir(parents=True, exist_ok=True)
    for path in sorted(folder.glob("*.lock")):
        slot = path.open("a+b")
        try:
            fcntl.flock(slot, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # a live process's
            slot.close()
            continue
        if path.exists():  # not removed between the glob and the lock
            return path.name.removesuffix(".lock"), slot
        slot.close()
    instance = uuid.uuid4().hex[:16]
    fresh: IO[bytes] = (folder / f"{instance}.lock").open("xb")
    fcntl.flock(fresh, fcntl.LOCK_EX | fcntl.LOCK_NB)  # new: nobody else can hold it
    return instance, fresh


class Lease:
    """A process's lease, renewed by a daemon thread until :meth:`stop`.

    Args:
        renew: writes the lease object (called at once, then every ``interval_s``).
        release: deletes it (called by :meth:`stop`).
        interval_s: seconds between renewals.
    """

    def __init__(
        self, renew: Callable[[], None], release: Callable[[], None], *, interval_s: float
    ) -> None:
        """Write the lease and start renewing it."""
        self._renew = renew
        self._release = release
        self._interval_s = interval_s
        self._stop = threading.Event()
        renew()
        self._thread = threading.Thread(target=self._run, name="loceval-lease", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._interval_s):
            try:
                self._renew()
            except Exception:  # the store is away: try again next time  # noqa: BLE001
                logger.warning("Could not renew this process's upload lease in the bucket")

    def stop(self) -> None:
        """Stop renewing and delete the lease (its uploads are then free to sweep)."""
        self._stop.set()
        if self._thread.ident != threading.get_ident():
            self._thread.join(timeout=10)
        with contextlib.suppress(Exception):
            self._release()
