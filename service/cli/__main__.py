"""``python -m service.cli``: the same as the ``loceval`` command."""

import sys

from service.cli import main

sys.exit(main())
