"""Suite-wide test settings.

Hypothesis runs derandomized by default, so every run of the suite (CI included) draws
the same examples: a failure is reproducible and no run passes or fails by luck. Set
``HYPOTHESIS_PROFILE=explore`` to draw fresh random examples (with more of them) while
hunting for bugs locally.

MuJoCo snapshots (a renderer process, a software GL context: seconds per run) are rendered
only by the tests that are about them, marked ``@pytest.mark.render``; every other test runs
with ``MUJOCO_GL=disable`` (in its own process and in the processes it starts), so an app's
snapshot is skipped with the reason in its summary.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from hypothesis import settings

settings.register_profile("deterministic", derandomize=True, deadline=None)
settings.register_profile("explore", derandomize=False, deadline=None, max_examples=2000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))


@pytest.fixture(autouse=True)
def _render_only_where_asked(request: pytest.FixtureRequest) -> Iterator[None]:
    if request.node.get_closest_marker("render") is not None:
        yield
        return
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("MUJOCO_GL", "disable")
        yield
