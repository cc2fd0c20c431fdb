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

import difflib
import inspect
import math
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import anyio

from openel_async.logs import get_logger

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

log = get_logger(__name__)


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
    units: dict[str, str] = field(default_factory=dict)
    """Component -> the unit of its positions (``rad``, ``m``; from its channel)."""
    labels: dict[str, str] = field(default_factory=dict)
    """Component -> the name to show, when not its component name (its channel's
    ``label``: the device's own name where the component's is derived from its class)."""

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
            unit = self.units.get(name, "")
            suffix = f" {unit}" if unit else ""
            recorded = self.recorded_final_positions.get(name)
            rec = "not recorded" if recorded is None else f"recorded {recorded:+.6f}{suffix}"
            label = self.labels.get(name, name)
            out.append(f"  {label:16} final {value:+.6f}{suffix} ({rec})")
        if not math.isnan(self.max_final_error):
            units = {self.units.get(n, "") for n in self.recorded_final_positions}
            unit = f" {units.pop()}" if len(units) == 1 and "" not in units else ""
            out.append(f"max final position difference {self.max_final_error:.3g}{unit}")
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


def sim_motor_class() -> type[Any]:
    """The ``sim`` driver's motor class (through the driver registry); LookupError when it
    is unavailable."""
    entry = next((e for e in discover_drivers() if e.name == "sim"), None)
    if entry is None or entry.info is None or "motor" not in entry.info.devices:
        reason = "not registered" if entry is None else entry.error
        raise LookupError(f"the sim driver's motor is unavailable: {reason}")
    return entry.info.devices["motor"]


def _motor_parameters(motor_class: type[Any]) -> dict[str, inspect.Parameter]:
    keyword = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return {
        name: p
        for name, p in inspect.signature(motor_class).parameters.items()
        if p.kind in keyword
    }


def check_motor_options(motor_class: type[Any], options: Mapping[str, Any]) -> None:
    """Raise ValueError for an option ``motor_class`` does not take (with "did you mean"
    and the options it takes) or a value it refuses (one motor is built to check them)."""
    parameters = _motor_parameters(motor_class)
    for key in options:
        if key not in parameters:
            close = difflib.get_close_matches(key, parameters, n=1)
            hint = f"did you mean {close[0]}? " if close else ""
            raise ValueError(
                f"{key!r} is not an option of the motor {motor_class.__name__} ({hint}it takes "
                f"{', '.join(sorted(parameters))})"
            )
    try:
        motor_class(**options)
    except (TypeError, ValueError) as exc:
        raise ValueError(str(exc)) from exc


def sim_rig(*, virtual: bool = True, **motor_options: Any) -> RigFactory:
    """A rig of the ``sim`` driver's motors, one per recorded actuator, built with
    ``motor_options`` (e.g. ``max_velocity=3.0``: checked now, :func:`check_motor_options`),
    on a virtual clock (instant) or, with ``virtual=False``, the real one."""
    motor_class = sim_motor_class()
    check_motor_options(motor_class, motor_options)

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
    channels = actuator_channels(recording)
    result = ReplayResult(
        recorded_final_positions=recorded_final_positions(recording),
        units={n: m["unit"] for n, m in channels.items() if "unit" in m},
        labels={n: m["label"] for n, m in channels.items() if "label" in m},
    )
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


def parse_options(items: Sequence[str], motor_class: type[Any] | None = None) -> dict[str, Any]:
    """``KEY=VALUE`` options for a rig; ValueError naming the option that is malformed. With
    ``motor_class``, each value is converted to the type of that option's default (a number,
    true/false, ``LOW,HIGH`` for a pair) and checked (:func:`check_motor_options`); without,
    numbers become floats and true/false bools."""
    parameters = {} if motor_class is None else _motor_parameters(motor_class)
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.isidentifier():
            raise ValueError(f"{item!r} is not KEY=VALUE (e.g. max_velocity=3.0)")
        if motor_class is not None and key in parameters:
            out[key] = _typed(key, text, parameters[key].default)
        else:
            out[key] = _guess(text)
    if motor_class is not None:
        check_motor_options(motor_class, out)
    return out


def _guess(text: str) -> Any:
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    try:
        return float(text)
    except ValueError:
        return text


def _typed(key: str, text: str, default: Any) -> Any:
    """``text`` as a value of the type of ``default``."""
    try:
        if isinstance(default, bool):
            if text.lower() not in ("true", "false"):
                raise ValueError
            return text.lower() == "true"
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
        if isinstance(default, tuple):
            parts = tuple(float(p) for p in text.split(","))
            if len(parts) != len(default):
                raise ValueError
            return parts
    except ValueError:
        if isinstance(default, tuple):
            expected = f"{len(default)} numbers separated by commas"
        else:
            expected = {bool: "true or false", int: "an integer"}.get(type(default), "a number")
        shown = ",".join(map(repr, default)) if isinstance(default, tuple) else repr(default)
        raise ValueError(
            f"{key}={text!r} is not allowed: expected {expected} (default {key}={shown})"
        ) from None
    return _guess(text) if default is inspect.Parameter.empty else text
