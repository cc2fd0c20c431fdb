"""``openel-async profile validate|show|convert FILE [OUT]``: work with RTC Profiles.

- ``validate FILE [--implementation]``: load and validate the profile, check every
  configuration default against its constraint and the execution type and rate; with
  ``--implementation`` also import the component class the profile names, which
  *executes* that module's code (only ``--implementation`` does: without it no code of
  the profile runs).
- ``show FILE``: a readable summary (identity, execution, actions, configuration,
  ports, implementation).
- ``convert FILE [OUT] [--to yaml|xml]``: rewrite the profile in the form OUT's suffix
  names, or print it (in the other form unless ``--to`` says) when OUT is omitted. OUT's
  suffix and folder are checked before FILE is read; OUT is written whole or not at all.

Exit status: 0 on success, 1 when the profile is invalid or OUT cannot be written (the
message names the file at fault), 2 when FILE does not exist.
"""

from __future__ import annotations

import argparse
import inspect
import os
import sys
from pathlib import Path

from .options import EXIT_USAGE, no_such_file

__all__ = ["add_parser", "run"]

OUT_SUFFIXES = (".yaml", ".yml", ".xml")


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``profile`` command to the CLI's subparsers."""
    profile = subparsers.add_parser(
        "profile", help="validate, show or convert an RTC Profile (.yaml/.yml/.xml)"
    )
    actions = profile.add_subparsers(dest="profile_action", required=True)
    validate = actions.add_parser(
        "validate", help="check a profile (exit status 1 if invalid, 2 if missing)"
    )
    validate.add_argument("file", help="RTC Profile (.yaml, .yml or .xml)")
    validate.add_argument(
        "--implementation",
        action="store_true",
        help="also import the component class the profile names: this EXECUTES the Python "
        "module its 'implementation' parameter names (next to the profile, or installed); "
        "use it only on profiles you trust",
    )
    show = actions.add_parser("show", help="print a summary of a profile")
    show.add_argument("file", help="RTC Profile (.yaml, .yml or .xml)")
    convert = actions.add_parser("convert", help="rewrite a profile as YAML or XML")
    convert.add_argument("file", help="RTC Profile (.yaml, .yml or .xml)")
    convert.add_argument(
        "out",
        nargs="?",
        help="output file (.yaml, .yml or .xml: the suffix selects the form) in an existing "
        "folder; written whole or not at all",
    )
    convert.add_argument(
        "--to", choices=("yaml", "xml"), help="form printed when OUT is omitted (default: other)"
    )


def run(args: argparse.Namespace) -> int:
    """Run the ``profile`` command parsed by :func:`add_parser`."""
    from ..rtc.configuration import ConfigurationError
    from ..rtc.profile import ProfileError

    action: str = args.profile_action
    path = Path(args.file)
    if no_such_file(f"openel-async profile {action}", args.file):
        return EXIT_USAGE
    if action == "convert" and args.out is not None:
        problem = _check_out(Path(args.out))
        if problem is not None:
            print(f"{args.out}: {problem}", file=sys.stderr)
            return 1
    try:
        if action == "validate":
            return _validate(path, bool(args.implementation))
        if action == "show":
            return _show(path)
        if action == "convert":
            return _convert(path, args.out, args.to)
    except FileNotFoundError as exc:  # a file the profile names
        print(
            f"openel-async profile {action}: {exc.filename or path}: no such file", file=sys.stderr
        )
        return EXIT_USAGE
    except OSError as exc:
        print(f"{path}: {exc}", file=sys.stderr)
        return 1
    except ProfileError as exc:
        print(f"{path}: invalid: {exc}", file=sys.stderr)
        return 1
    except ConfigurationError as exc:
        print(f"{path}: invalid configuration: {exc}", file=sys.stderr)
        return 1
    print(f"unknown profile action {action!r}", file=sys.stderr)
    return 2


def _validate(path: Path, implementation: bool) -> int:
    from ..rtc.profile import load_profile
    from ..rtc.runner import build_configuration, execution_spec, load_implementation

    profile = load_profile(path)
    spec = execution_spec(profile)
    config = build_configuration(profile)
    detail = spec.describe()
    line = (
        f"OK: {path}: {profile.id} ({profile.basic_info.component_kind}), {detail}, "
        f"{len(config.parameters)} configuration parameter(s)"
    )
    if implementation:
        cls = load_implementation(profile, path)
        line += f", implementation {cls.__qualname__} from {inspect.getsourcefile(cls)}"
    print(line)
    return 0


def _show(path: Path) -> int:
    from ..rtc.constraints import describe
    from ..rtc.profile import ProfileError, load_profile
    from ..rtc.runner import IMPLEMENTATION_PARAMETER, execution_spec

    profile = load_profile(path)
    b = profile.basic_info
    # A summary of what the profile says: a context openel-async cannot run is shown too.
    try:
        spec = execution_spec(profile)
    except ProfileError as exc:
        rate = f" at {b.execution_rate:g} Hz" if b.execution_rate is not None else ""
        execution = f"{b.execution_type}{rate} (openel-async cannot run it: {exc})"
    else:
        execution = b.execution_type
        if spec.ext_trig:
            execution += f" (one cycle per tick, nominal rate {spec.rate_hz:g} Hz)"
        elif spec.rate_hz is not None:
            execution += f" at {spec.rate_hz:g} Hz"
    out = [
        f"id              {profile.id}",
        f"name            {b.name} ({b.category}, vendor {b.vendor}, version {b.version})",
        f"kind            {b.component_kind}, {b.component_type}, activity {b.activity_type}",
        f"execution       {execution}",
    ]
    if b.description:
        out.append(f"description     {b.description}")
    implemented = [name for name, status in profile.actions.items() if status.implemented]
    out.append(f"actions         {', '.join(implemented) or '(none implemented)'}")
    impl = next((p for p in profile.parameters if p.name == IMPLEMENTATION_PARAMETER), None)
    named = (impl.default_value or "") if impl is not None else f"(by name: {b.name})"
    out.append(f"implementation  {named}")
    if profile.configurations:
        out.append("configuration")
        for c in profile.configurations:
            constraint = f"  [{describe(c.constraint)}]" if c.constraint is not None else ""
            unit = f" {c.unit}" if c.unit else ""
            out.append(f"  {c.name:<14} {c.type:<10} = {_shown(c.default_value)}{unit}{constraint}")
    for port in profile.data_ports:
        out.append(f"port            {port.name} ({port.port_type}, {port.type})")
    for sport in profile.service_ports:
        out.append(f"service port    {sport.name} ({len(sport.interfaces)} interface(s))")
    others = [p for p in profile.parameters if p.name != IMPLEMENTATION_PARAMETER]
    for param in others:
        out.append(f"parameter       {param.name} = {_shown(param.default_value)}")
    print("\n".join(out))
    return 0


def _shown(value: object) -> str:
    """A value as a person reads it: a string as it is (quoted only when empty or padded)."""
    if value is None:
        return "(none)"
    text = str(value)
    return f'"{text}"' if text != text.strip() or not text else text


def _check_out(out: Path) -> str | None:
    """What makes ``convert``'s OUT unusable, or None."""
    if out.suffix.lower() not in OUT_SUFFIXES:
        return f"unknown profile format {out.suffix!r} (use .yaml, .yml or .xml)"
    folder = out.absolute().parent
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        return f"cannot write: the folder {folder} {what}"
    if out.is_dir():
        return "cannot write: is a folder"
    return None


def _write_whole(target: Path, text: str) -> None:
    """Write ``text`` to a temporary file next to ``target``, then rename it."""
    temporary = target.with_name(f".{target.name}.partial-{os.getpid()}")
    try:
        temporary.write_text(text, encoding="utf-8")
        os.replace(temporary, target)
    finally:
        temporary.unlink(missing_ok=True)


def _convert(path: Path, out: str | None, to: str | None) -> int:
    from ..rtc.profile import dumps_xml, dumps_yaml, load_profile

    profile = load_profile(path)
    if out is not None:
        target = Path(out)
        text = dumps_xml(profile) if target.suffix.lower() == ".xml" else dumps_yaml(profile)
        try:
            _write_whole(target, text)
        except OSError as exc:
            print(f"{out}: cannot write: {exc.strerror or exc}", file=sys.stderr)
            return 1
        print(f"wrote {out}", file=sys.stderr)
        return 0
    form = to or ("yaml" if path.suffix.lower() == ".xml" else "xml")
    sys.stdout.write(dumps_xml(profile) if form == "xml" else dumps_yaml(profile))
    return 0
