"""The records the tap queues and the writer process turns into messages: ``(channel,
time_ns, kind, *fields)`` tuples (cheap to build in the control loop), and
:func:`to_message`, the JSON message of each (:mod:`.schemas`)."""

from __future__ import annotations

import struct
from typing import Any

from ..requests import Request
from .scene import poses_from_bytes, poses_message
from .schemas import (
    FRAME_TRANSFORMS,
    HAL_RECORD,
    JOINT_STATES,
    LOG,
    SCENE_UPDATE,
    TIMER_TICK,
    Schema,
    stamp,
)

# Entry kinds: (channel, time_ns, kind, *fields).
(
    COMMAND,
    READING,
    STATE,
    EVENT,
    COMPLETION,
    ERROR,
    TICK,
    JOINTS,
    LOG_LINE,
    MESSAGE,
    POSES,
    POSE_BYTES,
) = range(12)
CHANNEL = -1
"""(-1, offset_ns, 0, id, topic, schema_name, metadata): a new channel; its messages' log
time is their time plus ``offset_ns``."""
STATS = -2
"""(-2, queued, dropped, capacity): the parent's final statistics."""
BATCH = -3
"""(-3, time_ns, COMMAND, request, channels, values): a bank's batch of commands, one record
for ``len(channels)`` messages: ``values[i]`` to channel ``channels[i]`` (the writer process
makes each its COMMAND message on its component's channel)."""

COLUMNS = -4
"""(-4, kind, request, channels, width, times, values): a column's records
(:mod:`.columns`): ``times`` the int64 and ``values`` the float64 arrays as bytes (the
machine's byte order: the writer process runs beside the parent)."""

SCHEMAS: dict[str, Schema] = {
    s.name: s for s in (HAL_RECORD, TIMER_TICK, JOINT_STATES, LOG, FRAME_TRANSFORMS, SCENE_UPDATE)
}
HEADER = struct.Struct("<I")


REQUEST_NAMES: dict[int | None, str] = {int(r): r.name for r in Request}
"""Request code -> its name (None: a Sensor's value, ``VALUE``)."""
REQUEST_NAMES[None] = "VALUE"
_EVENT_NAMES = {EVENT: "event", COMPLETION: "completion", ERROR: "error"}


def _request_name(code: int | None) -> str:
    name = REQUEST_NAMES.get(code)
    if name is None:
        raise ValueError(f"unknown request code {code!r}")
    return name


def _joint(name: str, commanded: float | None, position: float | None) -> dict[str, Any]:
    joint: dict[str, Any] = {"name": name}
    if commanded is not None:
        joint["commanded"] = commanded
    if position is not None:
        joint["position"] = position
    return joint


def to_message(entry: list[Any]) -> dict[str, Any]:
    """The JSON message of an entry (see :mod:`.schemas`); the frequent kinds first."""
    kind = entry[2]
    if kind == COMMAND:
        _, t, _, request, value = entry
        return {"kind": "command", "time_ns": t, "request": _request_name(request), "value": value}
    if kind == TICK:
        _, t, _, index, deadline, missed, ticks = entry
        return {
            "time_ns": t,
            "index": index,
            "deadline_ns": deadline,
            "lateness_ns": t - deadline,
            "missed_ticks": missed,
            "ticks": ticks,
        }
    if kind == READING:
        _, t, _, request, values = entry
        reading = {"kind": "reading", "time_ns": t, "request": _request_name(request)}
        if values:  # no value: left out (the schema says number)
            reading["value"] = values[0]
        reading["values"] = values
        return reading
    _, t, _, *f = entry
    if kind == STATE:
        return {"kind": "state", "time_ns": t, "state": f[1], "old_state": f[0]}
    if kind in _EVENT_NAMES:
        return {"kind": _EVENT_NAMES[kind], "time_ns": t, "id": f[0]}
    if kind == JOINTS:  # an unknown value is left out (the schema says number)
        return {
            "timestamp": stamp(f[0]),
            "time_ns": t,
            "joints": [_joint(n, c, a) for n, c, a in f[1]],
        }
    if kind == LOG_LINE:
        return {
            "timestamp": stamp(f[0]),
            "level": f[1],
            "message": f[2],
            "name": f[3],
            "file": "",
            "line": 0,
        }
    if kind == POSES:  # (log_time, frames, flat poses): a scene's body poses
        return poses_message(f[1], f[2], f[0])
    if kind == POSE_BYTES:  # (log_time, frames, positions, orientations): the same, as bytes
        return poses_message(f[1], poses_from_bytes(f[2], f[3]), f[0])
    message: dict[str, Any] = f[0]  # MESSAGE: a ready dict
    return message
