"""``python -m piezo_fmu_harness``: the ``piezo-fmu`` command line."""

import sys

from piezo_fmu_harness.cli import main

sys.exit(main())
