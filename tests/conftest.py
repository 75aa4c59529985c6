"""Test-wide settings: the hypothesis profile.

``ci`` (the default) is derandomised, so every run, in CI and locally, tries the same examples
and a failure reproduces exactly.  ``TETHER_GYM_HYPOTHESIS=explore`` draws fresh random examples
instead, to hunt for new failures; each test keeps its own ``max_examples``.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, database=None, print_blob=True)
settings.register_profile("explore", derandomize=False, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("TETHER_GYM_HYPOTHESIS", "ci"))
