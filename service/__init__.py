"""The application layer: the command line and the HTTP service, the two front doors.

``service.cli`` is the command line (a module per command), ``service.main`` builds the HTTP
service; both turn their options into the core's with ``service.jobs.options`` and run an
evaluation with ``service.jobs.runner``.

Importing this package (which the ``loceval`` command does first, before numpy) runs
OpenBLAS on one thread unless ``OPENBLAS_NUM_THREADS`` says otherwise. Two reasons: a
multi-threaded ``dot`` or ``matmul`` sums in an order that depends on the machine's core
count, so the same recording's RMSE differed in its last digit between machines (measured:
0.05196714319883702 on two threads, ...701 on one); and OpenBLAS's idle threads spin after
each call, taking a core from the threads loceval runs itself (the chunked text parser, the
bootstrap), about 0.1 s of CPU on a 200,000-pose evaluation. The core (``loceval``) sets no
such thing: a program that imports it as a library keeps its own BLAS settings.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
