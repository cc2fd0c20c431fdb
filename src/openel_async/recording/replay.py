"""``openel-async replay``: a recording's commands fed to a rig at their recorded times, to
reproduce a run.

A rig is an async context manager giving a :class:`ReplayRig`: a clock and one
:class:`~openel_async.Actuator` per recorded actuator (by the recorded component name). The
built-in :func:`sim_rig` makes them from the ``sim`` driver's motor class (found through the
driver registry: the framework imports no driver), on a virtual clock (instant) or the real
one; a driver can offer its own (``openel_mujoco.foxglove_scene:replay_rig`` for the MuJoCo
arms). Each command is sent with ``set_value`` when the rig's clock reaches its recorded time
(relative to the first command); after the last, the replay runs to the recording's end and
reads every actuator's final position, compared with the recorded one.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import anyio
import structlog

from ..actuator import Actuator
from ..clock import Clock, MonotonicClock, VirtualClock
from ..errors import HALError
from ..registry import discover_drivers
from ..requests import Request
from .reader import Recording
from .schemas import JOINT_STATES_TOPIC

__all__ = [
    "RecordedCommand",
    "ReplayResult",
    "ReplayRig",
    "RigFactory",
    "actuator_channels",
    "recorded_commands",
    "recorded_final_positions",
    "replay",
    "sim_rig",
]

log = structlog.get_logger(__name__)


@dataclass(frozen=True, slots=True)
class RecordedCommand:
    component: str
    time_ns: int
    """On the recorded app's clock."""
    request: Request
    value: float


@dataclass
class ReplayRig:
    clock: Clock
    actuators: Mapping[str, Actuator]
    """By recorded component name."""
    name: str = "rig"


RigFactory = Callable[[Recording], AbstractAsyncContextManager[ReplayRig]]


@dataclass
class ReplayResult:
    commands: int = 0
    """Commands sent."""
    refused: list[tuple[str, str]] = field(default_factory=list)
    """(component, reason) of the commands the rig refused."""
    duration_s: float = 0.0
    """Replayed time on the rig's clock."""
    final_positions: dict[str, float] = field(default_factory=dict)
    recorded_final_positions: dict[str, float] = field(default_factory=dict)

    @property
    def max_final_error(self) -> float:
        """Largest |replayed - recorded| final position (NaN: nothing to compare)."""
        errors = [
            abs(self.final_positions[n] - v)
            for n, v in self.recorded_final_positions.items()
            if n in self.final_positions
        ]
        return max(errors) if errors else math.nan

    def lines(self) -> list[str]:
        out = [
            f"commands    {self.commands} sent, {len(self.refused)} refused, "
            f"{self.duration_s:.3f} s replayed"
        ]
        for name, value in self.final_positions.items():
            recorded = self.recorded_final_positions.get(name)
            rec = "not recorded" if recorded is None else f"recorded {recorded:+.6f}"
            out.append(f"  {name:16} final {value:+.6f} ({rec})")
        if not math.isnan(self.max_final_error):
            out.append(f"max final position difference {self.max_final_error:.3g}")
        return out


def actuator_channels(recording: Recording) -> dict[str, dict[str, str]]:
    """The recorded actuators: component name -> channel metadata."""
    return {
        c.metadata["component"]: c.metadata
        for c in recording.channels.values()
        if c.metadata.get("kind") == "actuator" and "component" in c.metadata
    }


def recorded_commands(recording: Recording) -> list[RecordedCommand]:
    """Every recorded command of every actuator, in time order."""
    names = actuator_channels(recording)
    out: list[RecordedCommand] = []
    for topic, data in recording.iter_topic_prefix("/hal/"):
        name = topic.removeprefix("/hal/")
        if name in names and data.get("kind") == "command":
            out.append(
                RecordedCommand(name, data["time_ns"], Request[data["request"]], data["value"])
            )
    out.sort(key=lambda c: c.time_ns)
    return out


def recorded_final_positions(recording: Recording) -> dict[str, float]:
    """Each actuator's last recorded actual position: its last POSITION_ACTUAL reading, else
    its last joint-state sample."""
    names = actuator_channels(recording)
    final: dict[str, float] = {}
    for sample in recording.topic(JOINT_STATES_TOPIC):
        for joint in sample["joints"]:
            if joint.get("position") is not None:
                final[joint["name"]] = float(joint["position"])
    for topic, data in recording.iter_topic_prefix("/hal/"):
        name = topic.removeprefix("/hal/")
        reading = data.get("kind") == "reading" and data.get("request") == "POSITION_ACTUAL"
        if name in names and reading:
            final[name] = float(data["value"])
    return final


def _end_ns(recording: Recording) -> int | None:
    times = [d["time_ns"] for _, d in recording.iter_topic_prefix("/hal/") if "time_ns" in d]
    return max(times) if times else None


def sim_rig(*, virtual: bool = True, **motor_options: Any) -> RigFactory:
    """A rig of the ``sim`` driver's motors, one per recorded actuator, built with
    ``motor_options`` (e.g. ``max_velocity=3.0``), on a virtual clock (instant) or, with
    ``virtual=False``, the real one."""
    entry = next((e for e in discover_drivers() if e.name == "sim"), None)
    if entry is None or entry.info is None or "motor" not in entry.info.devices:
        reason = "not registered" if entry is None else entry.error
        raise LookupError(f"the sim driver's motor is unavailable: {reason}")
    motor_class = entry.info.devices["motor"]

    @asynccontextmanager
    async def factory(recording: Recording) -> AsyncIterator[ReplayRig]:
        clock: Clock = VirtualClock() if virtual else MonotonicClock()
        async with AsyncExitStack() as stack:
            if isinstance(clock, VirtualClock):
                await stack.enter_async_context(clock.autojump())
            actuators = {}
            for name in actuator_channels(recording):
                actuator = Actuator(motor_class(**motor_options), device_name=name, clock=clock)
                actuators[name] = await stack.enter_async_context(actuator)
            yield ReplayRig(clock, actuators, "sim motors (openel_sim)")

    return factory


async def replay(
    recording: Recording,
    rig: RigFactory,
    *,
    settle_timeout_s: float = 30.0,
    on_command: Callable[[RecordedCommand], None] | None = None,
) -> ReplayResult:
    """Send the recording's commands to ``rig`` at their recorded times; see the module
    docstring. ``settle_timeout_s`` bounds (in real time) the wait for the last motions."""
    commands = recorded_commands(recording)
    result = ReplayResult(recorded_final_positions=recorded_final_positions(recording))
    if not commands:
        raise ValueError(f"{recording.path}: no recorded commands to replay")
    end_ns = max(_end_ns(recording) or 0, commands[-1].time_ns)
    t0 = commands[0].time_ns
    async with rig(recording) as parts:
        missing = sorted({c.component for c in commands} - set(parts.actuators))
        if missing:
            raise LookupError(f"the rig has no actuator for {missing}")
        clock = parts.clock
        start = clock.now_ns()
        motions = {}
        for command in commands:
            deadline = start + (command.time_ns - t0)
            if clock.now_ns() < deadline:
                await clock.sleep_until(deadline)
            actuator = parts.actuators[command.component]
            try:
                motions[command.component] = await actuator.set_value(
                    command.value, command.request
                )
            except HALError as exc:
                result.refused.append((command.component, str(exc)))
                continue
            result.commands += 1
            if on_command is not None:
                on_command(command)
        await clock.sleep_until(start + (end_ns - t0))
        with anyio.move_on_after(settle_timeout_s):
            for motion in motions.values():
                if not motion.done():
                    try:
                        await motion
                    except HALError as exc:
                        log.warning("replay_motion_failed", error=str(exc))
        result.duration_s = (clock.now_ns() - start) / 1e9
        for name, actuator in parts.actuators.items():
            try:
                result.final_positions[name] = await actuator.get_value(Request.POSITION_ACTUAL)
            except HALError as exc:
                log.warning("replay_read_failed", component=name, error=str(exc))
    return result


def parse_options(items: Sequence[str]) -> dict[str, Any]:
    """``KEY=VALUE`` options for a rig (numbers as floats, true/false as bools)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.isidentifier():
            raise ValueError(f"--option must be KEY=VALUE, not {item!r}")
        value: Any = text
        if text.lower() in ("true", "false"):
            value = text.lower() == "true"
        else:
            with contextlib.suppress(ValueError):
                value = float(text)
        out[key] = value
    return out
