"""Suite-wide test settings.

Hypothesis runs derandomized by default, so every run of the suite (CI included) draws
the same examples: a failure is reproducible and no run passes or fails by luck. Set
``HYPOTHESIS_PROFILE=explore`` to draw fresh random examples (with more of them) while
hunting for bugs locally.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("deterministic", derandomize=True, deadline=None)
settings.register_profile("explore", derandomize=False, deadline=None, max_examples=2000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))
