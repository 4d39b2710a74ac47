"""``python -m service.cli``: the same as the ``loceval`` command."""

import sys

from service.cli import run

sys.exit(run())
