"""``python -m rigsim`` is the ``rigsim`` command."""

import sys

from rigsim.cli import main

sys.exit(main())
