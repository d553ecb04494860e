"""``python -m explore3d``: the command line (see :mod:`explore3d.cli`)."""
import sys

from .cli import main

sys.exit(main())
