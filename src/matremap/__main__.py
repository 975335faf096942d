"""``python -m matremap``: the command line (as the ``matremap`` script)."""

import sys

from matremap.cli import main

sys.exit(main())
