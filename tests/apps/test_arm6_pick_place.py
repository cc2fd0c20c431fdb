"""The arm6 pick and place (openel_async.cli.arm6_pick_place, apps/arm6_pick_place.py) end to
end, in lockstep: the whole sequence moves the box."""

from __future__ import annotations

import io
import math
from pathlib import Path

import anyio
import pytest

from openel_apps import arm6_pick_place as app
from openel_apps.arm_demo import ArmOptions
from openel_apps.arm_rig import open_arm_rig
from openel_async import Actuator, BadParameterError, NotImplementedHALError, Request
from openel_async.app import AppContext, AppHook, LiveLine
from openel_async.component import HALComponent
from openel_async.testing import EventRecorder
from openel_mujoco import MujocoEffector, MujocoEventId, MujocoSim

from .conftest import assert_snapshot_written_or_explained, is_png, load


class Names(AppHook):
    def __init__(self) -> None:
        self.names: list[str] = []

    def component_added(self, ctx: AppContext, component: HALComponent) -> None:
        self.names.append(component.device_name)


@pytest.mark.render
async def test_pick_and_place_moves_the_box(tmp_path: Path) -> None:
    options = ArmOptions(duration=8.0, realtime=False, out_dir=tmp_path, live=False, period_ms=2.0)
    sim = MujocoSim("arm6", keyframe="home")
    stream = io.StringIO()
    names = Names()
    with anyio.fail_after(40):
        result = await app.run_pick_place(
            sim,
            options=options,
            place=(0.20, 0.40),
            live=LiveLine(stream),
            ctx=AppContext(hooks=[names]),
        )
    # The components carry the names the app gave them (issue 21 point 7).
    assert names.names == [*app.JOINTS, "suction", "tool_pos", "pad_touch"]
    assert "suction" in stream.getvalue() and "tool (" in stream.getvalue()  # live progress

    steps = [step.name for step in result.steps]
    assert steps == [
        "home", "above box", "down", "suction on", "lift", "move", "down", "suction off", "up",
        "home",
    ]  # fmt: skip
    motions = [step for step in result.steps if step.motion_id is not None]
    assert len(motions) == 7
    assert all(step.outcome == "succeeded" for step in motions)
    assert all(step.setpoint_spread_ticks <= 1 for step in motions)  # joints arrive together

    # The pad touched the box when the suction came on, and the box came up with the tool.
    assert result.gripped and result.grip_force_n > 1.0
    assert result.carried
    # It ended on the floor at the place location, 47 cm from where it was.
    assert result.box_start_m == pytest.approx((0.45, 0.0, 0.02), abs=1e-6)
    assert result.box_end_m[2] == pytest.approx(0.02, abs=2e-3)
    assert result.place_error_m < 0.01
    assert result.box_moved_m > 0.4
    # The tool is back home (pointing along +x at (0.43, 0, 0.5)).
    assert result.steps[-1].tool_m == pytest.approx((0.43, 0.0, 0.5), abs=5e-3)

    assert is_png(result.artifacts.plot)
    assert_snapshot_written_or_explained(result.artifacts)
    assert all(is_png(path) for _, path in result.artifacts.extra)  # start and lift snapshots
    text = "\n".join(result.lines())
    assert "box                picked and carried" in text
    assert "box moved          from (+0.450, +0.000, +0.020) m to" in text


def test_the_app_refuses_an_unreachable_place(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from openel_async.cli import main as cli_main

    code = cli_main(
        ["run", "apps/arm6_pick_place.py", "--place", "0.9", "0", "--out", str(tmp_path)]
    )
    assert code == 2
    assert "error: --place 0.9 0: tool point (0.900, 0.000, " in capsys.readouterr().err
    code = cli_main(["run", "apps/arm6_pick_place.py", "--place", "nan", "0"])
    assert code == 2
    assert "error: --place nan 0: two finite numbers of m" in capsys.readouterr().err
    code = cli_main(["run", "apps/arm6_pick_place.py", "--duration", "2", "--out", str(tmp_path)])
    assert code == 2
    err = capsys.readouterr().err
    assert "error: --duration 2: the sequence takes at least 4.60 s of arm motion" in err
    assert not list(tmp_path.iterdir())  # nothing ran, nothing written


def test_the_shortest_sequence_is_the_planners_limit() -> None:
    sim = app.open_sim(realtime=False)
    shortest = app.min_duration_s(sim, app.DEFAULT_PLACE_M)
    assert shortest is not None
    app.plan_pick_place(sim, app.DEFAULT_PLACE_M, shortest)  # plans
    with pytest.raises(app.SequenceTooFastError, match=f"at least {shortest:.2f} s"):
        app.plan_pick_place(sim, app.DEFAULT_PLACE_M, shortest - 0.1)


def test_the_apps_file_is_a_thin_wrapper_of_the_package() -> None:
    wrapper = load("arm6_pick_place")
    assert wrapper.main is app.main and wrapper.run_pick_place is app.run_pick_place
    assert wrapper.Arm6Kinematics is app.Arm6Kinematics


async def test_the_suction_cup_is_the_drivers_effector() -> None:
    rig = app.arm6_rig()  # the app's rig file
    sim = app.open_sim(realtime=False, rig=rig)
    events = EventRecorder(sim.clock)
    async with open_arm_rig(rig, sim) as opened:
        assert list(opened.components) == [*app.JOINTS, "suction", "tool_pos", "pad_touch"]
        assert list(sim.joints) == list(app.JOINTS) and list(sim.sensors) == [
            "tool_pos",
            "pad_touch",
        ]
        suction = opened.actuator("suction")
        cup = suction.device
        assert cup is sim.effectors["suction"]
        assert isinstance(cup, MujocoEffector) and cup.kind == "adhesion"
        assert cup.limits.torque == pytest.approx(20.0)  # gain 20 N x ctrl 1
        suction.add_observer(events)
        with anyio.fail_after(10):
            await (await suction.set_value(12.0, Request.TORQUE))
        assert cup.on and not cup.holding  # on, but the pad touches nothing at home
        assert await suction.get_value(Request.TORQUE_ACTUAL) == pytest.approx(12.0)
        with pytest.raises(BadParameterError):
            await suction.set_value(25.0, Request.TORQUE)  # beyond the actuator's force
        with pytest.raises(BadParameterError):
            await suction.set_value(-1.0, Request.TORQUE)
        with pytest.raises(NotImplementedHALError):
            await suction.set_value(1.0, Request.POSITION)
        await suction.set_value(0.0, Request.NO_EXCITE)
        assert not cup.on
        await sim.sleep(0.01)
        assert math.isclose(await suction.get_value(Request.TORQUE_ACTUAL), 0.0)
    assert events.count("event", MujocoEventId.HOLDING) == 0
    # Without a name (outside a rig), the component is named after the device's kind.
    bare = Actuator(MujocoSim("arm6").effector("suction"), clock=sim.clock)
    assert bare.device_name == "HalKind128MuJoCoSuction"  # kind 0x80: not in the registry
