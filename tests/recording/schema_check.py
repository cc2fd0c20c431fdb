"""A hand check of a JSON message against the JSON Schema of its channel (the subset the
recorder's schemas use: type, properties, required, items, enum), for tests without the
``jsonschema`` package."""

from __future__ import annotations

from typing import Any

_TYPES: dict[str, tuple[type, ...]] = {
    "object": (dict,),
    "array": (list,),
    "string": (str,),
    "number": (int, float),
    "integer": (int,),
    "boolean": (bool,),
}


def problems(schema: dict[str, Any], value: Any, where: str = "$") -> list[str]:
    """What in ``value`` breaks ``schema`` (empty: nothing)."""
    out: list[str] = []
    kind = schema.get("type")
    if kind is not None:
        ok = isinstance(value, _TYPES[kind]) and not (
            kind in ("number", "integer") and isinstance(value, bool)
        )
        if not ok:
            return [f"{where}: {value!r} is not of type {kind}"]
    if "enum" in schema and value not in schema["enum"]:
        out.append(f"{where}: {value!r} is not one of {schema['enum']}")
    if isinstance(value, dict):
        out += [
            f"{where}: {key!r} is required"
            for key in schema.get("required", ())
            if key not in value
        ]
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                out += problems(sub, value[key], f"{where}.{key}")
    if isinstance(value, list) and "items" in schema:
        for i, item in enumerate(value):
            out += problems(schema["items"], item, f"{where}[{i}]")
    return out


def check_recording(path: Any) -> int:
    """Check every message of the MCAP file ``path`` (read with the ``mcap`` package) against
    its channel's schema; raises AssertionError with the first problems; the messages
    checked."""
    import json

    from mcap.reader import make_reader

    checked = 0
    found: list[str] = []
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert schema is not None and schema.encoding == "jsonschema"
            found += [
                f"{channel.topic} @{message.log_time}: {p}"
                for p in problems(json.loads(schema.data), json.loads(message.data))
            ]
            checked += 1
    assert not found, "\n".join(found[:20])
    return checked
