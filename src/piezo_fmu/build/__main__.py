"""``python -m piezo_fmu.build``: (re)build both FMUs (see :mod:`piezo_fmu.build.fmus`)."""

import sys

from piezo_fmu.build.fmus import main

sys.exit(main())
