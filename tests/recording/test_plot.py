"""``record plot``: the demos' look (actual solid C0, commanded dashed C1), the user's names
and units on the axes, the legend where it covers the fewest points, and a joint that barely
moves not blown up into noise."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import anyio
import pytest
from matplotlib.colors import to_rgba

from openel_async import Actuator, EventTimer, Request, VirtualClock
from openel_async.recording import Recorder, read_recording
from openel_async.recording.plot import joint_figure
from openel_sim import SimMotor


class _Shoulder(SimMotor):
    """A motor with a name of its own (its component's name is derived from its class)."""

    name = "shoulder"


async def _record(path: Path) -> None:
    """The shoulder moves 0 -> 0.8 rad; AXIS_STILL is told 0.002 rad: it barely moves."""
    clock = VirtualClock()
    async with clock.autojump(), Recorder(path) as recorder:
        moving = Actuator(_Shoulder(max_velocity=3.0), clock=clock)
        still = Actuator(SimMotor(), device_name="AXIS_STILL", clock=clock)
        timer = EventTimer(10, clock=clock, name="loop")
        for component in (moving, still):
            recorder.observe(component)
        recorder.observe_timer(timer)
        async with moving, still, timer:
            timer.start_timer()
            await moving.set_value(0.8, Request.POSITION)
            await still.set_value(0.002, Request.POSITION)
            await clock.sleep(1.0)
            timer.stop_timer()


async def test_the_plot_looks_like_the_demos(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    await _record(path)
    fig = joint_figure(read_recording(path))
    moving, still = (row for row in fig.axes)
    assert moving.get_ylabel() == "shoulder [rad]"  # not HalMotorOpenELSimMotor
    assert still.get_ylabel() == "AXIS_STILL [rad]"
    for ax in (moving, still):
        actual, commanded = ax.get_lines()
        assert actual.get_label() == "actual" and actual.get_linestyle() == "-"
        assert to_rgba(actual.get_color()) == to_rgba("C0")  # the demos' colours
        assert commanded.get_label() == "commanded" and commanded.get_linestyle() == "--"
        assert to_rgba(commanded.get_color()) == to_rgba("C1")
        assert any(y == y for y in actual.get_ydata())  # an actual curve, not just its name
    low, high = still.get_ylim()
    assert high - low == pytest.approx(0.1)  # not autoscaled into its noise
    assert low < 0.0 and high > 0.002 and (low + high) / 2 == pytest.approx(0.001, abs=1e-3)
    low, high = moving.get_ylim()
    assert high - low > 0.8  # a joint that moves keeps matplotlib's own limits
    legend = moving.get_legend()
    assert legend is not None and legend._loc == 0  # "best": where it covers the fewest points


def test_record_plot_command_writes_the_png(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    anyio.run(_record, path)
    result = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "record", "plot", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    out = tmp_path / "run_joints.png"
    assert result.stdout == f"plot  {out}\n"
    assert out.read_bytes().startswith(b"\x89PNG")
