"""The channels and message schemas of a recording and of the live view (the same for both).

Every message is JSON (``message_encoding`` ``"json"``) described by a JSON Schema
(``schema_encoding`` ``"jsonschema"``), as Foxglove reads them. Topics:

=========================  ==========================  =================================================
Topic                      Schema                      One message per
=========================  ==========================  =================================================
``/hal/<component>``       ``openel_async.HalRecord``  command, reading, event, completion, error, state
                                                       change of that component (``kind`` tells which)
``/timer/<timer>``         ``openel_async.TimerTick``  that EventTimer's tick statistics (ticks, lateness, missed)
``/joint_states``          ``openel_async.JointStates`` sample of every joint (commanded and actual)
``/log``                   ``foxglove.Log``            log line (info and above), on the app's clock
``/tf``                    ``foxglove.FrameTransforms`` sample of a scene's body poses (MuJoCo rigs)
``/scene``                 ``foxglove.SceneUpdate``    the scene's geometry (once, then on subscribe)
=========================  ==========================  =================================================

Times: ``log_time`` is wall-clock ns since 1970 (the app's clock shifted to the wall clock
at the start, on every channel); every message but ``/log``'s also carries ``time_ns``, the
time on the app's own clock (virtual or simulated time included), which replay uses. A value
that is not known is left out of its message (never ``null`` where a schema says number).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "FRAME_TRANSFORMS",
    "HAL_RECORD",
    "JOINT_STATES",
    "LOG",
    "SCENE_UPDATE",
    "TIMER_TICK",
    "ChannelSpec",
    "Schema",
    "hal_topic",
    "stamp",
    "timer_topic",
]

MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"
JOINT_STATES_TOPIC = "/joint_states"
LOG_TOPIC = "/log"
TF_TOPIC = "/tf"
SCENE_TOPIC = "/scene"


@dataclass(frozen=True)
class Schema:
    name: str
    schema: dict[str, Any]

    @property
    def data(self) -> bytes:
        return json.dumps(self.schema, sort_keys=True).encode()


@dataclass(frozen=True)
class ChannelSpec:
    """One channel: its id in the pipeline, topic, schema and metadata."""

    id: int
    topic: str
    schema: Schema
    metadata: dict[str, str] = field(default_factory=dict)


def hal_topic(component_name: str) -> str:
    return f"/hal/{component_name}"


def timer_topic(timer_name: str) -> str:
    return f"/timer/{timer_name}"


def stamp(time_ns: int) -> dict[str, int]:
    """A Foxglove ``time`` ({sec, nsec})."""
    sec, nsec = divmod(time_ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


_NUMBER = {"type": "number"}
_INT = {"type": "integer"}
_STR = {"type": "string"}
_TIME = {
    "type": "object",
    "properties": {"sec": _INT, "nsec": _INT},
    "required": ["sec", "nsec"],
}
_VEC3 = {"type": "object", "properties": {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER}}
_QUAT = {
    "type": "object",
    "properties": {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER, "w": _NUMBER},
}
_COLOR = {
    "type": "object",
    "properties": {"r": _NUMBER, "g": _NUMBER, "b": _NUMBER, "a": _NUMBER},
}
_POSE = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}

HAL_RECORD = Schema(
    "openel_async.HalRecord",
    {
        "title": "openel_async.HalRecord",
        "description": "One command, reading, event, completion, error or state change of an "
        "OpenEL component",
        "type": "object",
        "properties": {
            "kind": {
                "type": "string",
                "enum": ["command", "reading", "event", "completion", "error", "state"],
            },
            "time_ns": {**_INT, "description": "time on the app's clock"},
            "request": {**_STR, "description": "command or reading: the Request code's name"},
            "value": {**_NUMBER, "description": "command: the target; reading: the first value"},
            "values": {"type": "array", "items": _NUMBER, "description": "reading: all values"},
            "id": {**_INT, "description": "event or error: its id"},
            "state": {**_STR, "description": "state: the new state"},
            "old_state": _STR,
        },
        "required": ["kind", "time_ns"],
    },
)

TIMER_TICK = Schema(
    "openel_async.TimerTick",
    {
        "title": "openel_async.TimerTick",
        "description": "The statistics of an EventTimer's ticks since its previous message "
        "(one message per statistics period, at its last tick)",
        "type": "object",
        "properties": {
            "time_ns": {**_INT, "description": "the last tick's delivery time"},
            "index": {**_INT, "description": "the last tick's index"},
            "deadline_ns": {**_INT, "description": "the last tick's deadline"},
            "lateness_ns": {**_INT, "description": "the last tick's lateness"},
            "missed_ticks": {**_INT, "description": "periods skipped since the previous message"},
            "ticks": {**_INT, "description": "ticks delivered since the previous message"},
        },
        "required": ["time_ns", "index", "deadline_ns", "lateness_ns"],
    },
)

JOINT_STATES = Schema(
    "openel_async.JointStates",
    {
        "title": "openel_async.JointStates",
        "description": "Commanded and actual position of every joint (a motor); a value "
        "that is not known is left out",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "time_ns": _INT,
            "joints": {
                "type": "array",
                "items": {
                    "type": "object",
                    "required": ["name"],
                    "properties": {
                        "name": _STR,
                        "commanded": _NUMBER,
                        "position": {**_NUMBER, "description": "actual (left out: not known)"},
                    },
                },
            },
        },
        "required": ["time_ns", "joints"],
    },
)

LOG = Schema(
    "foxglove.Log",
    {
        "title": "foxglove.Log",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "level": {**_INT, "description": "1 debug, 2 info, 3 warning, 4 error, 5 fatal"},
            "message": _STR,
            "name": _STR,
            "file": _STR,
            "line": _INT,
        },
    },
)

FRAME_TRANSFORMS = Schema(
    "foxglove.FrameTransforms",
    {
        "title": "foxglove.FrameTransforms",
        "type": "object",
        "properties": {
            "transforms": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "parent_frame_id": _STR,
                        "child_frame_id": _STR,
                        "translation": _VEC3,
                        "rotation": _QUAT,
                    },
                },
            }
        },
    },
)

_PRIMITIVE = {
    "type": "object",
    "properties": {"pose": _POSE, "size": _VEC3, "color": _COLOR},
}
SCENE_UPDATE = Schema(
    "foxglove.SceneUpdate",
    {
        "title": "foxglove.SceneUpdate",
        "type": "object",
        "properties": {
            "deletions": {"type": "array", "items": {"type": "object"}},
            "entities": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "frame_id": _STR,
                        "id": _STR,
                        "lifetime": {
                            "type": "object",
                            "properties": {"sec": _INT, "nsec": _INT},
                        },
                        "frame_locked": {"type": "boolean"},
                        "metadata": {"type": "array", "items": {"type": "object"}},
                        "cubes": {"type": "array", "items": _PRIMITIVE},
                        "spheres": {"type": "array", "items": _PRIMITIVE},
                        "cylinders": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "properties": {
                                    "pose": _POSE,
                                    "size": _VEC3,
                                    "bottom_scale": _NUMBER,
                                    "top_scale": _NUMBER,
                                    "color": _COLOR,
                                },
                            },
                        },
                    },
                },
            },
        },
    },
)
