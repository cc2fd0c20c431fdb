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
import importlib
import importlib.util
import inspect
import sys
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any

import anyio

from ..app import AppInfo, AppUnavailable, Interrupted, find_app, run_app, run_interruptible
from .record_cmd import taps_from_args

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


def is_app_name(text: str) -> bool:
    """``text`` names a registered app rather than a file: an identifier, not a file here."""
    return text.isidentifier() and not Path(text).exists()


def _run_info(
    info: AppInfo, argv: list[str], prog: str, label: str, tap_args: argparse.Namespace | None
) -> int:
    hooks = [] if tap_args is None else taps_from_args(tap_args, "openel-async run")
    if hooks is None:
        return 2
    try:
        return run_app(info, argv, prog=prog, hooks=hooks, stop_label=label)
    except AppUnavailable as exc:
        print(f"{label}: {exc}", file=sys.stderr)
        return 1


def run(path_text: str, argv: list[str], tap_args: argparse.Namespace | None = None) -> int:
    """Run ``path_text``; ``tap_args``: the parsed ``--record``/``--foxglove`` options (for
    registered apps and APP_INFO modules, which register their components)."""
    if is_app_name(path_text):
        try:
            info = find_app(path_text)
        except LookupError as exc:
            print(f"openel-async run: {exc}", file=sys.stderr)
            return 2
        prog = f"openel-async run {path_text}"
        return _run_info(info, argv, prog, f"openel-async run: {path_text}", tap_args)
    path = Path(path_text)
    tapped = tap_args is not None and (tap_args.record is not None or tap_args.foxglove)
    if path.suffix.lower() in PROFILE_SUFFIXES:
        if tapped:
            print(
                "openel-async run: --record/--foxglove need an app (not a profile)", file=sys.stderr
            )
            return 2
        runner = importlib.import_module("openel_async.rtc.runner")
        return int(runner.run_profile_cli(path, argv))
    try:
        module = load_app(path)
    except AppLoadError as exc:
        print(f"openel-async run: {exc}", file=sys.stderr)
        return 2
    app_info = getattr(module, "APP_INFO", None)
    if isinstance(app_info, AppInfo):
        prog = f"openel-async run {path}"
        return _run_info(app_info, argv, prog, f"openel-async run: {path}", tap_args)
    if tapped:
        print(
            f"openel-async run: {path}: --record/--foxglove need an app that registers its "
            "components (an APP_INFO, docs/apps.md), not a bare main(argv)",
            file=sys.stderr,
        )
        return 2
    main: Any = module.main
    result = anyio.run(run_interruptible, partial(main, argv), backend="asyncio")
    if isinstance(result, Interrupted):
        print(f"\nsummary ({path}, interrupted)")
        for line in result.lines():
            print("  " + line)
        sys.stdout.flush()
        print(
            f"openel-async run: {path}: interrupted by {result.signum.name} "
            f"(exit status {result.exit_code})",
            file=sys.stderr,
        )
        return result.exit_code
    return int(result or 0)
