"""`python -m clvis.cli`: the same as `python -m clvis`."""

import sys

from . import main

sys.exit(main())
