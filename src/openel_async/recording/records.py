"""The records the tap queues and the writer process turns into messages: ``(channel,
time_ns, kind, *fields)`` tuples (cheap to build in the control loop), and
:func:`to_message`, the JSON message of each (:mod:`.schemas`)."""

from __future__ import annotations

import struct
from typing import Any

from ..requests import Request
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
COMMAND, READING, STATE, EVENT, COMPLETION, ERROR, TICK, JOINTS, LOG_LINE, MESSAGE = range(10)
CHANNEL = -1
"""(-1, offset_ns, 0, id, topic, schema_name, metadata): a new channel; its messages' log
time is their time plus ``offset_ns``."""
STATS = -2
"""(-2, queued, dropped, capacity): the parent's final statistics."""

SCHEMAS: dict[str, Schema] = {
    s.name: s for s in (HAL_RECORD, TIMER_TICK, JOINT_STATES, LOG, FRAME_TRANSFORMS, SCENE_UPDATE)
}
HEADER = struct.Struct("<I")


def _request_name(code: int | None) -> str:
    return "VALUE" if code is None else Request(code).name


def to_message(entry: list[Any]) -> dict[str, Any]:
    """The JSON message of an entry (see :mod:`.schemas`)."""
    _, t, kind, *f = entry
    if kind == COMMAND:
        return {"kind": "command", "time_ns": t, "request": _request_name(f[0]), "value": f[1]}
    if kind == READING:
        values = f[1]
        return {
            "kind": "reading",
            "time_ns": t,
            "request": _request_name(f[0]),
            "value": values[0] if values else None,
            "values": values,
        }
    if kind == STATE:
        return {"kind": "state", "time_ns": t, "state": f[1], "old_state": f[0]}
    if kind in (EVENT, COMPLETION, ERROR):
        name = {EVENT: "event", COMPLETION: "completion", ERROR: "error"}[kind]
        return {"kind": name, "time_ns": t, "id": f[0]}
    if kind == TICK:
        return {
            "time_ns": t,
            "index": f[0],
            "deadline_ns": f[1],
            "lateness_ns": t - f[1],
            "missed_ticks": f[2],
        }
    if kind == JOINTS:
        return {
            "timestamp": stamp(f[0]),
            "time_ns": t,
            "joints": [{"name": n, "commanded": c, "position": a} for n, c, a in f[1]],
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
    message: dict[str, Any] = f[0]  # MESSAGE: a ready dict
    return message
