"""``openel-async run NAME|PATH``: run a registered app, an application file or an RTC Profile.

- ``NAME`` (no path separator, no suffix, not an existing file): the app registered under
  that name in the ``openel_async.apps`` entry-point group (``openel-async demo --list``);
  the remaining arguments are its command line.
- ``*.yaml``, ``*.yml``, ``*.xml``: an RTC Profile; the component it names is built,
  hosted in the execution context its profile describes, and run until Ctrl-C.
- ``*.py`` or a directory with ``app.py``/``__init__.py``: a Python application that
  defines ``async def main(argv: list[str]) -> int | None``; the remaining command-line
  arguments are passed to it; or a module that defines ``APP_INFO``
  (an :class:`~openel_async.app.AppInfo`), run as a registered app would be. SIGINT
  (Ctrl-C) or SIGTERM cancels ``main`` (its clean-ups run), prints a short summary and exits
  with 130 or 143.

Both execute code: the application file, or the Python module a profile names.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import inspect
import sys
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any, NoReturn

import anyio

from ..app import AppInfo, AppUnavailable, Interrupted, find_app, run_app, run_interruptible
from .options import EXIT_USAGE, no_such_file
from .record_cmd import TAP_OPTIONS, add_tap_arguments, taps_from_args
from .rig_cmd import RIG_OPTIONS, add_rig_arguments

PROFILE_SUFFIXES = (".yaml", ".yml", ".xml")


class AppLoadError(Exception):
    """The path is not a runnable application."""


def load_app(path: Path) -> ModuleType:
    if path.is_dir():
        for candidate in ("app.py", "__init__.py"):
            if (path / candidate).is_file():
                path = path / candidate
                break
        else:
            raise AppLoadError(f"{path}: a directory app needs app.py or __init__.py")
    if not path.is_file():
        raise AppLoadError(f"{path}: no such application file")
    name = f"openel_app_{path.parent.name}_{path.stem}".replace("-", "_")
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise AppLoadError(f"{path}: cannot be imported as a Python module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    if isinstance(getattr(module, "APP_INFO", None), AppInfo):
        return module
    main = getattr(module, "main", None)
    if main is None or not inspect.iscoroutinefunction(main):
        raise AppLoadError(
            f"{path}: an application defines 'async def main(argv)' or an APP_INFO (AppInfo)"
        )
    return module


_TAP_FLAGS = frozenset({"--foxglove", "--sim"})  # the options after the name with no value
_PULLED = (*TAP_OPTIONS, *RIG_OPTIONS)


class TapOptionError(Exception):
    """A tap option after the app's name is malformed (no value, a bad port)."""


def split_tap_options(argv: list[str]) -> tuple[list[str], list[str]]:
    """``argv`` (what follows the app's name) split into the tap options openel-async takes
    (:data:`~.record_cmd.TAP_OPTIONS`, with their values) and the app's own arguments. A
    first ``--`` ends the search; it is dropped and everything after it is the app's."""
    taps: list[str] = []
    rest: list[str] = []
    tokens = iter(argv)
    for token in tokens:
        if token == "--":
            rest += tokens
            break
        name = token.split("=", 1)[0]
        if name not in _PULLED:
            rest.append(token)
            continue
        taps.append(token)
        if name not in _TAP_FLAGS and "=" not in token:
            value = next(tokens, None)
            if value is None:
                raise TapOptionError(f"{token} needs a value")
            taps.append(value)
    return taps, rest


def merge_tap_options(tap_args: argparse.Namespace, taps: list[str]) -> None:
    """Parse ``taps`` (from :func:`split_tap_options`) into ``tap_args``: given after the
    app's name, they override those given before it."""

    class _Parser(argparse.ArgumentParser):
        def error(self, message: str) -> NoReturn:
            raise TapOptionError(message)

    parser = _Parser(add_help=False, allow_abbrev=False)
    add_tap_arguments(parser)
    add_rig_arguments(parser)
    for action in parser._actions:
        action.default = argparse.SUPPRESS
    parser.parse_args(taps, namespace=tap_args)


@contextlib.contextmanager
def refuse_shadowed(options: set[str], label: str) -> Iterator[None]:
    """While the app runs, an argparse option of the app named like one of ``options`` (tap
    options openel-async took from after the app's name) stops it with exit status 2: the
    option would be ambiguous."""
    if not options:
        yield
        return
    original = argparse._ActionsContainer.add_argument  # groups' options too

    def add_argument(self: argparse._ActionsContainer, *args: Any, **kwargs: Any) -> Any:
        action = original(self, *args, **kwargs)
        clash = sorted(options.intersection(action.option_strings))
        if clash:
            print(
                f"{label}: the app has an option {clash[0]} of its own: give openel-async's "
                f"{clash[0]} before the app's name, and the app's after '--'",
                file=sys.stderr,
            )
            raise SystemExit(EXIT_USAGE)
        return action

    argparse._ActionsContainer.add_argument = add_argument  # type: ignore[method-assign]
    try:
        yield
    finally:
        argparse._ActionsContainer.add_argument = original  # type: ignore[method-assign]


def is_app_name(text: str) -> bool:
    """``text`` names a registered app rather than a file: an identifier, not a file here."""
    return text.isidentifier() and not Path(text).exists()


PROG = "openel-async run"


def _run_info(
    info: AppInfo, argv: list[str], prog: str, label: str, tap_args: argparse.Namespace | None
) -> int:
    hooks = [] if tap_args is None else taps_from_args(tap_args, PROG)
    if hooks is None:
        return 2
    rig = getattr(tap_args, "rig", None)
    if rig is not None and no_such_file(PROG, rig):
        return EXIT_USAGE
    try:
        return run_app(
            info,
            argv,
            prog=prog,
            hooks=hooks,
            stop_label=label,
            rig=rig,
            sim=bool(getattr(tap_args, "sim", False)),
        )
    except AppUnavailable as exc:
        print(f"{label}: {exc}", file=sys.stderr)
        return 1


def run(path_text: str, argv: list[str], tap_args: argparse.Namespace | None = None) -> int:
    """Run ``path_text``; ``tap_args``: the parsed ``--record``/``--foxglove`` options (for
    registered apps and APP_INFO modules, which register their components), completed by
    those found in ``argv`` (after the app's name, before a ``--``)."""
    pulled: set[str] = set()
    if tap_args is not None:
        try:
            taps, argv = split_tap_options(argv)
            merge_tap_options(tap_args, taps)
        except TapOptionError as exc:
            print(f"{PROG}: {exc}", file=sys.stderr)
            return EXIT_USAGE
        pulled = {t.split("=", 1)[0] for t in taps} & set(_PULLED)
    with refuse_shadowed(pulled, f"{PROG} {path_text}"):
        return _run(path_text, argv, tap_args)


def _run(path_text: str, argv: list[str], tap_args: argparse.Namespace | None) -> int:
    if is_app_name(path_text):
        try:
            info = find_app(path_text)
        except LookupError as exc:
            print(f"{PROG}: {exc}", file=sys.stderr)
            return EXIT_USAGE
        prog = f"{PROG} {path_text}"
        return _run_info(info, argv, prog, f"{PROG}: {path_text}", tap_args)
    if no_such_file(PROG, path_text, folder_ok=True):
        return EXIT_USAGE
    path = Path(path_text)
    tapped = tap_args is not None and (tap_args.record is not None or tap_args.foxglove)
    rigged = tap_args is not None and (
        getattr(tap_args, "rig", None) is not None or getattr(tap_args, "sim", False)
    )
    if path.suffix.lower() in PROFILE_SUFFIXES:
        if rigged:
            print(f"{PROG}: --rig/--sim need an app that opens a rig (not a profile)",
                  file=sys.stderr)  # fmt: skip
            return EXIT_USAGE
        if tapped:
            print(f"{PROG}: --record/--foxglove need an app (not a profile)", file=sys.stderr)
            return EXIT_USAGE
        runner = importlib.import_module("openel_async.rtc.runner")
        return int(runner.run_profile_cli(path, argv))
    try:
        module = load_app(path)
    except AppLoadError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    app_info = getattr(module, "APP_INFO", None)
    if isinstance(app_info, AppInfo):
        prog = f"{PROG} {path}"
        return _run_info(app_info, argv, prog, f"{PROG}: {path}", tap_args)
    if rigged:
        print(
            f"{PROG}: {path}: --rig/--sim need an app that opens a rig (an APP_INFO with "
            "takes_rig=True, docs/apps.md), not a bare main(argv)",
            file=sys.stderr,
        )
        return EXIT_USAGE
    if tapped:
        print(
            f"{PROG}: {path}: --record/--foxglove need an app that registers its "
            "components (an APP_INFO, docs/apps.md), not a bare main(argv)",
            file=sys.stderr,
        )
        return EXIT_USAGE
    main: Any = module.main
    try:
        result = anyio.run(run_interruptible, partial(main, argv), backend="asyncio")
    except SystemExit as exc:  # the app's argparse (or the option clash above)
        return exc.code if isinstance(exc.code, int) else 1
    if isinstance(result, Interrupted):
        print(f"\nsummary ({path}, interrupted)")
        for line in result.lines():
            print("  " + line)
        sys.stdout.flush()
        print(
            f"{PROG}: {path}: interrupted by {result.signum.name} (exit status {result.exit_code})",
            file=sys.stderr,
        )
        return result.exit_code
    return int(result or 0)
