"""`python -m clvis`: the clvis command line."""

import sys

from .cli import entry

sys.exit(entry())
