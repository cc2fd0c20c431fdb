"""The real profiles of tests/rtc/data/real run, each with a small Python implementation
written next to it (the originals are C++/Java components)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from openel_async import VirtualClock
from openel_async.rtc import LifeCycleState
from openel_async.rtc.configuration import ConfigurationError
from openel_async.rtc.profile import load_profile
from openel_async.rtc.runner import run_profile

REAL = Path(__file__).parents[1] / "rtc" / "data" / "real"
PROFILES = sorted(p for p in REAL.iterdir() if p.suffix in (".xml", ".yaml"))

IMPLEMENTATION = """
from openel_async.rtc import CallbackResult, RTObject


class {name}(RTObject):
    executed = 0

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        self.executed += 1
        return None

    def report(self) -> dict[str, str]:
        return {{"executed": str(self.executed)}}
"""


def _snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.name)
async def test_real_profiles_run(path: Path, tmp_path: Path, virtual_clock: VirtualClock) -> None:
    profile = load_profile(path)
    name = profile.basic_info.name
    copy = tmp_path / f"RTC{path.suffix}"
    shutil.copy(path, copy)
    (tmp_path / f"{_snake(name)}.py").write_text(IMPLEMENTATION.format(name=name))
    if path.name == "RtcSampleVer02.xml":
        # Its own default breaks its own constraint (see the README): one clear error.
        with pytest.raises(ConfigurationError, match="parameter 'config2': value 'Sample'"):
            await run_profile(copy, duration_s=0.05, clock=virtual_clock, handle_signals=False)
        return
    summary = await run_profile(copy, duration_s=0.05, clock=virtual_clock, handle_signals=False)
    assert summary.rate_hz == profile.basic_info.execution_rate == 1000.0
    assert summary.final_state is LifeCycleState.ACTIVE
    assert 45 <= summary.cycles <= 50
