"""open_rig on simulated devices: names, limits on every command path, e-stop latch, and the
safe stop on every exit path."""

from __future__ import annotations

from pathlib import Path

import anyio
import anyio.lowlevel
import pytest

from openel_async import ActuatorBank, BadParameterError, HALError, Request, VirtualClock
from openel_async.device import ErrorId
from openel_async.rig import load_rig, open_rig
from openel_async.safety import ExitAction

RIG = """\
namespace: lab
components:
  - name: MOTOR_1
    driver: sim
    device: motor
    params: {max_velocity: 3.0, max_acceleration: 40.0}
    limits: {position: [-1.0, 1.0], velocity: 2.0, acceleration: 20}
  - name: MOTOR_2
    driver: sim
    device: motor
    params: {max_velocity: 3.0, max_acceleration: 40.0}
    limits: {velocity: 2.0, acceleration: 20}
  - name: ENCODER_1
    driver: sim
    device: encoder
    params: {motor: {ref: MOTOR_1}}
timers:
  sync: {period_ms: 10}
groups:
  arm: {axes: [MOTOR_1, MOTOR_2], timer: sync, limits: {max_jerk: 500}}
safety: {on_exit: ON_EXIT}
"""


def _rig(tmp_path: Path, on_exit: str = "hold") -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(RIG.replace("ON_EXIT", on_exit))
    return path


class Errors:
    def __init__(self) -> None:
        self.seen: list[tuple[str, int]] = []

    def notify_event(self, source: object, event_id: int) -> None:
        pass

    def notify_error(self, source: object, error_id: int) -> None:
        self.seen.append((getattr(source, "device_name", "?"), int(error_id)))


async def test_components_timers_and_groups_by_name(tmp_path: Path) -> None:
    clock = VirtualClock()
    async with clock.autojump(), open_rig(load_rig(_rig(tmp_path)), clock) as rig:
        assert [a.device_name for a in rig.actuators] == ["MOTOR_1", "MOTOR_2"]
        assert [s.device_name for s in rig.sensors] == ["ENCODER_1"]
        assert rig.timer("sync").period_ms == 10
        group = rig.group("arm")
        motion = await group.move_to([0.5, -0.5])
        await motion
        assert await rig.actuator("MOTOR_1").get_value(Request.POSITION_ACTUAL) == pytest.approx(
            0.5, abs=1e-2
        )
        with pytest.raises(
            BadParameterError, match=r"component of the rig .*allowed: ENCODER_1, MOTOR_1, MOTOR_2"
        ):
            rig.component("MOTOR_l")
        with pytest.raises(BadParameterError, match="an actuator"):
            rig.actuator("ENCODER_1")


async def test_limits_apply_to_set_value_and_to_streamed_batches(tmp_path: Path) -> None:
    clock = VirtualClock()
    async with clock.autojump(), open_rig(load_rig(_rig(tmp_path)), clock) as rig:
        m1 = rig.actuator("MOTOR_1")
        with pytest.raises(BadParameterError, match=r"a position in \[-1.0, 1.0\]"):
            await m1.set_value(1.5, Request.POSITION)
        with pytest.raises(BadParameterError, match="velocity"):
            await m1.set_value(2.5, Request.VELOCITY)
        await m1.set_value(2.0, Request.VELOCITY)  # the limit itself is allowed
        bank = ActuatorBank(rig.actuators)
        with pytest.raises(BadParameterError):
            bank.set_values_nowait([1.5, 0.0], Request.POSITION)
        bank.set_values_nowait([0.9, 3.0], Request.POSITION)  # MOTOR_2: only its own (+-pi)
        # re_init keeps them: the device's limits are set again each time it becomes Active
        m1.device.inject_fault(ErrorId.DEVICE_ERROR, "test")  # type: ignore[attr-defined]
        await anyio.lowlevel.checkpoint()
        await m1.re_init()
        with pytest.raises(BadParameterError):
            await m1.set_value(1.5, Request.POSITION)


async def test_estop_latches_until_released(tmp_path: Path) -> None:
    clock = VirtualClock()
    errors = Errors()
    async with clock.autojump(), open_rig(load_rig(_rig(tmp_path)), clock) as rig:
        for component in rig.components.values():
            component.add_observer(errors)
        await rig.estop()
        assert rig.estopped
        assert {c.state.value for c in rig.components.values()} == {"Error"}
        await anyio.sleep(0.01)
        assert sorted(errors.seen) == [
            ("ENCODER_1", ErrorId.ESTOP), ("MOTOR_1", ErrorId.ESTOP), ("MOTOR_2", ErrorId.ESTOP)
        ]  # fmt: skip
        with pytest.raises(HALError, match="e-stop is not released"):
            await rig.actuator("MOTOR_1").re_init()
        rig.release_estop()
        for component in rig.components.values():
            await component.re_init()
        await rig.actuator("MOTOR_1").set_value(0.2, Request.POSITION)


@pytest.mark.parametrize("on_exit", ["hold", "stop", "torque_off"])
async def test_normal_exit_leaves_every_actuator_in_on_exit(tmp_path: Path, on_exit: str) -> None:
    clock = VirtualClock()
    async with clock.autojump():
        async with open_rig(load_rig(_rig(tmp_path, on_exit)), clock) as rig:
            await rig.actuator("MOTOR_1").set_value(2.0, Request.VELOCITY)
            await anyio.sleep(0.1)
        assert [(r.component, r.action, r.ok) for r in rig.exit_report] == [
            ("MOTOR_1", ExitAction(on_exit), True),
            ("MOTOR_2", ExitAction(on_exit), True),
        ]
        # sim motors have no safe stop of their own: the HAL fallback
        expected = {"hold": "position hold", "stop": "velocity 0", "torque_off": "NO_EXCITE"}
        assert rig.exit_report[0].how == expected[on_exit]
        assert f"on exit            {on_exit}: MOTOR_1 done, MOTOR_2 done" == rig.exit_line()


async def test_an_exception_still_leaves_the_actuators_safe(tmp_path: Path) -> None:
    clock = VirtualClock()
    opened = []
    async with clock.autojump():
        with pytest.raises(RuntimeError, match="app bug"):
            async with open_rig(load_rig(_rig(tmp_path, "stop")), clock) as rig:
                opened.append(rig)
                await rig.actuator("MOTOR_1").set_value(2.0, Request.VELOCITY)
                raise RuntimeError("app bug")
    assert all(r.ok for r in opened[0].exit_report)
    assert len(opened[0].exit_report) == 2


async def test_a_cancellation_still_leaves_the_actuators_safe(tmp_path: Path) -> None:
    clock = VirtualClock()
    opened = []
    async with clock.autojump():
        with anyio.move_on_after(0.5):
            async with open_rig(load_rig(_rig(tmp_path, "stop")), clock) as rig:
                opened.append(rig)
                await rig.actuator("MOTOR_1").set_value(2.0, Request.VELOCITY)
                await anyio.sleep_forever()
    assert [r.ok for r in opened[0].exit_report] == [True, True]
    assert opened[0].exit_report[0].how == "velocity 0"


async def test_an_estopped_actuator_is_left_in_its_emergency_state(tmp_path: Path) -> None:
    clock = VirtualClock()
    async with clock.autojump():
        async with open_rig(load_rig(_rig(tmp_path, "hold")), clock) as rig:
            await rig.actuator("MOTOR_1").estop()
        assert rig.exit_report[0].how.startswith("e-stopped")
        assert rig.exit_report[1].how == "position hold"
        assert rig.exit_line() == "on exit            hold: MOTOR_1 e-stopped, MOTOR_2 done"


async def test_a_group_cannot_stream_past_the_rig_limits(tmp_path: Path) -> None:
    clock = VirtualClock()
    async with clock.autojump(), open_rig(load_rig(_rig(tmp_path)), clock) as rig:
        with pytest.raises(BadParameterError, match="MOTOR_1"):
            await rig.group("arm").move_to([1.5, 0.0])
        # the planning uses the rig's velocity limit: 2 rad/s, not the motor's 3
        assert [lim.max_velocity for lim in rig.group("arm").limits] == [2.0, 2.0]
