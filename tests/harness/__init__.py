"""The servers tests and benchmarks run against, started the same way for both.

- :mod:`tests.harness.ports`: free loopback ports.
- :mod:`tests.harness.processes`: ``loceval serve`` / ``worker`` (or any server) as a
  subprocess whose output is kept, readiness by ``/readyz``, a stop that always ends it.
- :mod:`tests.harness.seaweedfs`: a SeaweedFS (``weed server -s3``) on loopback ports.
- :mod:`tests.harness.databases`: a fresh database on the machine's PostgreSQL, an empty
  Redis database number, and a PostgreSQL and a Redis of one's own to stop and start.

Nothing here depends on pytest: what a machine lacks raises
:class:`HarnessUnavailableError`, which the tests' fixtures turn into a skip (a failure in CI)
and a benchmark prints.
"""

from __future__ import annotations

__all__ = ["HarnessUnavailableError"]


class HarnessUnavailableError(RuntimeError):
    """A binary or server this machine lacks (its message says what to install or start)."""
