"""``python -m harness``: the ``piezo-fmu`` command line."""

import sys

from harness.cli import main

sys.exit(main())
