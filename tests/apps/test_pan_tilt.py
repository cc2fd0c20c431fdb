"""The pan-tilt app takes its hardware from a rig file: the shipped ``rigs/pantilt-sim.yaml``
by default, any other through its configuration parameter ``rig``."""

from __future__ import annotations

from collections.abc import AsyncIterator, Mapping
from contextlib import asynccontextmanager
from pathlib import Path

import pytest

from openel_apps.pan_tilt import PROFILE, RIGS, SIM_RIG
from openel_apps.pan_tilt import pan_tilt as module
from openel_apps.pan_tilt.pan_tilt import PanTilt, rig_path
from openel_async import BadParameterError, Request, VirtualClock
from openel_async.rig import ResolvedRig, parse_rig
from openel_async.rtc.profile import load_profile
from openel_async.rtc.runner import build_configuration, run_profile_cli

OTHER_RIG = """\
description: a narrow head
namespace: narrow
components:
  - {name: tilt, driver: sim, device: motor, limits: {position: [-0.2, 0.2]}}
  - {name: pan, driver: sim, device: motor, limits: {position: [-0.5, 0.5]}}
safety: {on_exit: stop}
"""


@asynccontextmanager
async def initialized(settings: Mapping[str, str] | None = None) -> AsyncIterator[PanTilt]:
    """A PanTilt on the virtual clock with the profile's configuration (and ``settings``),
    initialized; finalized at the end."""
    configuration = build_configuration(load_profile(PROFILE), settings)
    component = PanTilt("head", configuration=configuration, clock=VirtualClock())
    await component.on_initialize()
    try:
        yield component
    finally:
        await component.on_finalize()


def other_rig(directory: Path) -> Path:
    path = directory / "narrow.yaml"
    path.write_text(OTHER_RIG)
    return path


async def test_the_shipped_rig_limits_reach_the_actuators() -> None:
    async with initialized() as component:
        assert component.rig is not None
        assert component.rig.spec.source == str(SIM_RIG)
        assert component.pan is not None and component.tilt is not None
        assert component.pan.device.limits.position == (-2.9, 2.9)
        assert component.tilt.device.limits.position == (-1.2, 1.2)
        # beyond the rig's limits, within the SimMotor's own (-pi, pi): refused
        with pytest.raises(BadParameterError, match=r"a position in \[-2\.9, 2\.9\]"):
            await component.pan.set_value(3.0, Request.POSITION)
        with pytest.raises(BadParameterError, match=r"a position in \[-1\.2, 1\.2\]"):
            await component.tilt.set_value(-1.3, Request.POSITION)
        await component.pan.set_value(2.8, Request.POSITION)
        await component.tilt.set_value(-1.1, Request.POSITION)
        assert await component.pan.get_value(Request.POSITION) == 2.8


async def test_the_rig_parameter_points_at_another_rig_file(tmp_path: Path) -> None:
    path = other_rig(tmp_path)
    async with initialized({"rig": str(path)}) as component:
        assert component.rig is not None and component.rig.spec.source == str(path)
        assert component.pan is not None and component.tilt is not None
        with pytest.raises(BadParameterError, match=r"a position in \[-0\.5, 0\.5\]"):
            await component.pan.set_value(0.6, Request.POSITION)
        await component.tilt.set_value(0.2, Request.POSITION)
    # the other rig's safety.on_exit left its actuators (in its file order)
    assert component.report()["on exit"] == "stop: tilt done, pan done"
    assert component.pan is None and component.tilt is None


def test_a_run_says_which_rig_and_how_it_left_the_axes(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert run_profile_cli(PROFILE, ["--virtual", "--duration", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "rig                pantilt-sim.yaml (pan-tilt head on simulated motors" in out
    assert "on exit            hold: pan done, tilt done" in out
    path = other_rig(tmp_path)
    argv = ["--virtual", "--duration", "0.5", "--set", f"rig={path}", "--set", "amplitude=0.1"]
    assert run_profile_cli(PROFILE, argv) == 0
    out = capsys.readouterr().out
    assert f"rig                {path} (a narrow head)" in out
    assert "on exit            stop: tilt done, pan done" in out
    assert "state at the end   ACTIVE" in out


def test_a_scan_beyond_the_rig_limits_puts_the_component_in_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    argv = ["--virtual", "--duration", "2", "--set", f"rig={other_rig(tmp_path)}"]
    assert run_profile_cli(PROFILE, [*argv, "--set", "amplitude=1.0"]) == 0
    out = capsys.readouterr().out
    assert "state at the end   ERROR" in out  # tilt 0.5 sin(...) passed 0.2
    assert "on exit            stop: tilt done, pan done" in out


def test_rig_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert rig_path("pantilt-sim.yaml") == SIM_RIG == RIGS / "pantilt-sim.yaml"
    monkeypatch.chdir(tmp_path)
    other_rig(tmp_path)
    assert rig_path("narrow.yaml") == Path("narrow.yaml")  # the current directory first
    (tmp_path / "pantilt-sim.yaml").write_text(OTHER_RIG)
    assert rig_path("pantilt-sim.yaml") == Path("pantilt-sim.yaml")
    assert rig_path(str(SIM_RIG)) == SIM_RIG
    for text in ("", "missing.yaml", "sub/pantilt-sim.yaml", "rigs"):
        with pytest.raises(BadParameterError, match=r"shipped rig \(.*pantilt-sim\.yaml"):
            rig_path(text)


async def test_a_rig_without_pan_and_tilt_is_refused_before_it_opens(tmp_path: Path) -> None:
    path = tmp_path / "arm.yaml"
    path.write_text(OTHER_RIG.replace("name: tilt", "name: elbow"))
    with pytest.raises(BadParameterError, match=r"it has no tilt; its components: elbow, pan"):
        async with initialized({"rig": str(path)}):
            pass


async def test_a_rig_with_buses_is_refused_on_the_virtual_clock(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    data = {
        "buses": {"can0": {"type": "can", "channel": "can0"}},
        "components": [
            {"name": "pan", "driver": "sim", "device": "motor"},
            {"name": "tilt", "driver": "sim", "device": "motor"},
        ],
    }
    spec = parse_rig(data, "bus-rig")
    monkeypatch.setattr(module, "resolve_rig", lambda _: ResolvedRig(spec, {}, {}))
    with pytest.raises(BadParameterError, match="buses run in real time"):
        async with initialized():
            pass


def test_the_cli_names_a_missing_rig(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--virtual", "--duration", "1", "--set", "rig=no-such-rig.yaml"]
    assert run_profile_cli(PROFILE, argv) == 1
    err = capsys.readouterr().err
    assert "on_initialize failed" in err


def test_run_pantilt_rig_option_becomes_its_rig_setting(tmp_path: Path) -> None:
    """``openel-async run pantilt --rig FILE`` runs on that file (its configuration's
    ``rig``), not the shipped one."""
    import subprocess
    import sys

    shipped = (
        Path(__file__).resolve().parents[2] / "apps" / "openel_apps" / "rigs" / "pantilt-sim.yaml"
    )
    rig = tmp_path / "narrow-head.yaml"
    rig.write_text(
        shipped.read_text().replace("description: pan-tilt head", "description: narrow head")
    )
    result = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "run", "pantilt", "--rig", str(rig),
         "--virtual", "--duration", "1"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "narrow-head.yaml (narrow head" in result.stdout
