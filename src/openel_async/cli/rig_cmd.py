"""``openel-async rig check|show|schema``, and the ``--rig FILE`` / ``--sim`` options of
``openel-async run`` (docs/hardware.md)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from .options import EXIT_USAGE, no_such_file

__all__ = ["RIG_OPTIONS", "add_parser", "add_rig_arguments", "run"]

RIG_OPTIONS = ("--rig", "--sim")
"""The options of :func:`add_rig_arguments`: ``run`` takes them after the app's name too."""


def add_rig_arguments(parser: argparse.ArgumentParser) -> None:
    """``--rig FILE`` and ``--sim``."""
    group = parser.add_argument_group("hardware (docs/hardware.md)")
    group.add_argument(
        "--rig",
        metavar="RIG.yaml",
        default=None,
        help="the rig file the app opens instead of its own: buses, components, timers, "
        "groups, safety ('openel-async rig check' checks it)",
    )
    group.add_argument(
        "--sim",
        action="store_true",
        default=False,
        help="run the rig against simulated peers: every bus becomes a simulated one with "
        "the simulated devices at the same addresses",
    )


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    rig = sub.add_parser("rig", help="check a rig file, show what it opens, or print its schema")
    rig_sub = rig.add_subparsers(dest="rig_command", required=True, metavar="COMMAND")
    check = rig_sub.add_parser(
        "check",
        help="check a rig file against the installed drivers without opening anything",
    )
    check.add_argument("rig", metavar="RIG.yaml", help="the rig file")
    show = rig_sub.add_parser("show", help="print what a rig file would open")
    show.add_argument("rig", metavar="RIG.yaml", help="the rig file")
    show.add_argument(
        "--sim", action="store_true", help="say what --sim would open instead of the buses"
    )
    rig_sub.add_parser(
        "schema",
        help="print the JSON Schema of a rig file, with the options of every installed bus type",
    )


def run(args: argparse.Namespace) -> int:
    label = f"openel-async rig {args.rig_command}"
    if args.rig_command == "schema":
        print(json.dumps(full_schema(), indent=2))
        return 0
    if no_such_file(label, args.rig):
        return EXIT_USAGE
    from ..errors import BadParameterError
    from ..rig import load_rig, resolve_rig

    try:
        resolved = resolve_rig(load_rig(args.rig))
    except BadParameterError as exc:
        print(f"{label}: {exc}", file=sys.stderr)
        return 1
    if args.rig_command == "check":
        for line in check_lines(resolved):
            print(line)
        return 0
    for line in show_lines(resolved, sim=args.sim):
        print(line)
    return 0


def check_lines(resolved: Any) -> list[str]:
    """``RIG.yaml: ok (...)`` and a warning line for each thing a careful user would want
    to know."""
    from ..device import ActuatorDevice
    from ..safety import EmergencyStop, Watchdog

    spec = resolved.spec
    actuators = [c for c in spec.components if issubclass(resolved.classes[c.name], ActuatorDevice)]
    lines = [
        f"{spec.source}: ok ({_count(len(spec.buses), 'bus', 'buses')}, "
        f"{_count(len(spec.components), 'component')} of which "
        f"{_count(len(actuators), 'actuator')}, {_count(len(spec.timers), 'timer')}, "
        f"{_count(len(spec.groups), 'group')})"
    ]
    watched = [c.name for c in spec.components if issubclass(resolved.classes[c.name], Watchdog)]
    if watched and spec.safety.watchdog_timeout is None:
        lines.append(
            f"warning: safety.watchdog_timeout is null: the watchdogs of {', '.join(watched)} "
            "are not armed (the drives keep going if the host dies)"
        )
    no_estop = [
        c.name for c in actuators if not issubclass(resolved.classes[c.name], EmergencyStop)
    ]
    if no_estop and spec.buses:
        lines.append(
            f"note: {', '.join(no_estop)} have no emergency state of their own: an e-stop "
            "faults them on the host and sends them nothing more"
        )
    for name, bus in resolved.buses.items():
        if bus.load is not None:
            lines.append(f"bus {name}: {bus.load.fraction:.0%} load ({bus.load.detail})")
            if bus.load.fraction > 0.7:
                lines.append(
                    f"warning: bus {name} is {bus.load.fraction:.0%} loaded: little room for "
                    "SDO, EMCY and retransmissions"
                )
    unlimited = [c.name for c in actuators if c.limits.is_empty()]
    if unlimited and spec.buses:
        lines.append(f"note: no limits for {', '.join(unlimited)} (only the device's own)")
    return lines


def _count(n: int, one: str, many: str | None = None) -> str:
    return f"{n} {one if n == 1 else (many or one + 's')}"


def show_lines(resolved: Any, *, sim: bool) -> list[str]:
    """What opening the rig would open, one thing a line."""
    spec = resolved.spec
    lines = [f"rig {spec.source} (namespace {spec.namespace!r})"]
    if spec.buses:
        lines.append("buses")
    for name, bus in resolved.buses.items():
        if sim:
            devices = ", ".join(d.name for d in bus.devices) or "no device"
            lines.append(f"  {name}: simulated {bus.spec.type} bus with peers for {devices}")
            lines.append(f"    instead of {bus.kind.describe(bus.options)}")
        else:
            lines.append(f"  {name}: {bus.kind.describe(bus.options)}")
        if bus.load is not None:
            lines.append(f"    load {bus.load.fraction:.0%}: {bus.load.detail}")
    lines.append("components")
    for c in spec.components:
        cls = resolved.classes[c.name]
        where = f" on {c.bus}" if c.bus is not None else ""
        params = ", ".join(f"{k}={v!r}" for k, v in c.params.items())
        lines.append(f"  {c.name}: {c.driver}.{c.device} ({cls.__name__}){where}"
                     + (f" {params}" if params else ""))  # fmt: skip
        limits = c.limits
        shown = []
        if limits.position is not None:
            shown.append(f"position [{limits.position[0]:g}, {limits.position[1]:g}]")
        for key in ("velocity", "acceleration", "torque"):
            value = getattr(limits, key)
            if value is not None:
                shown.append(f"{key} {value:g}")
        if shown:
            lines.append(f"    limits {', '.join(shown)}")
    if spec.timers:
        lines.append("timers")
        for t in spec.timers:
            lines.append(f"  {t.name}: every {t.period_ms:g} ms")
    if spec.groups:
        lines.append("groups")
        for g in spec.groups:
            lines.append(f"  {g.name}: {', '.join(g.axes)} on timer {g.timer}, max jerk "
                         f"{g.max_jerk:g}, {g.synchronization} synchronization")  # fmt: skip
    s = spec.safety
    watchdog = "not armed" if s.watchdog_timeout is None else f"{s.watchdog_timeout:g} s"
    lines.append(
        f"safety: watchdog {watchdog}, on exit {s.on_exit.value} (at most "
        f"{s.exit_timeout:g} s each), SIGQUIT e-stop {'on' if s.estop_on_sigquit else 'off'}"
    )
    return lines


def full_schema() -> dict[str, Any]:
    """The rig's JSON Schema; ``buses`` entries are one of the installed bus types' options,
    each with its ``type``."""
    import msgspec

    from ..registry import discover_drivers
    from ..rig.spec import RigDoc

    kinds = {
        name: kind
        for entry in discover_drivers()
        if entry.info is not None
        for name, kind in entry.info.buses.items()
    }
    types = [RigDoc, *(k.options_type for k in kinds.values())]
    (root, *options), components = msgspec.json.schema_components(types)
    variants = []
    for name, ref in zip(kinds, options, strict=True):
        target = components[ref["$ref"].rsplit("/", 1)[1]]
        target.setdefault("properties", {})["type"] = {"const": name}
        target.setdefault("required", []).insert(0, "type")
        target["additionalProperties"] = False
        variants.append(ref)
    rig_doc = components[root["$ref"].rsplit("/", 1)[1]]
    buses = rig_doc["properties"]["buses"]
    for choice in buses.get("anyOf", [buses]):
        if choice.get("type") == "object":
            choice["additionalProperties"] = {"anyOf": variants} if variants else {}
    for cls in (*_structs(RigDoc), *(k.options_type for k in kinds.values())):
        schema = components.get(cls.__name__)
        if schema is None:
            continue
        for field_name, text in field_docs(cls).items():
            prop = schema.get("properties", {}).get(field_name)
            if prop is not None:
                prop.setdefault("description", text)
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "openel-async rig file",
        **root,
        "$defs": components,
    }


def _structs(root: type) -> list[type]:
    """``root`` and the Struct types its fields use, once each."""
    import msgspec

    seen: list[type] = []
    todo = [root]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen.append(cls)
        info = msgspec.inspect.type_info(cls)
        stack: list[Any] = [f.type for f in getattr(info, "fields", ())]
        while stack:
            t = stack.pop()
            if isinstance(t, msgspec.inspect.StructType):
                todo.append(t.cls)
            for attr in ("types", "item_type", "key_type", "value_type", "item_types"):
                inner = getattr(t, attr, None)
                if isinstance(inner, tuple):
                    stack.extend(inner)
                elif inner is not None:
                    stack.append(inner)
    return seen


def field_docs(cls: type) -> dict[str, str]:
    """The docstring written under each field of a class (``x: int`` then ``\"\"\"...\"\"\"``),
    joined into one line: the schema's descriptions come from the code's own documentation."""
    import ast
    import inspect
    import itertools
    import textwrap

    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError, SyntaxError):
        return {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    docs: dict[str, str] = {}
    for node, after in itertools.pairwise(body):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs
