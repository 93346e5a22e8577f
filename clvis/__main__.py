"""`python -m clvis`: the clvis command line."""

import sys

from .cli import main

sys.exit(main())
