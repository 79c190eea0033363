"""Hypothesis profiles: ``ci`` (the default, 500 examples), ``long`` (10 000) and ``dev`` (50)."""

import os

from hypothesis import settings

settings.register_profile("ci", max_examples=500, derandomize=True, print_blob=True)
settings.register_profile("long", max_examples=10_000, print_blob=True)
settings.register_profile("dev", max_examples=50, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
