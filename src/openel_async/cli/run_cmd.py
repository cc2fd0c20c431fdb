"""``openel-async run PATH``: run an application file or an RTC Profile.

- ``*.yaml``, ``*.yml``, ``*.xml``: an RTC Profile; the component it names is built,
  hosted in the execution context its profile describes, and run until Ctrl-C.
- ``*.py`` or a directory with ``app.py``/``__init__.py``: a Python application that
  defines ``async def main(argv: list[str]) -> int | None``; the remaining command-line
  arguments are passed to it.  SIGINT (Ctrl-C) or SIGTERM cancels ``main`` (its clean-ups
  run), prints a short summary and exits with 130 or 143.

Both execute code: the application file, or the Python module a profile names.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any

import anyio

from .interrupt import Interrupted, run_interruptible

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
    main = getattr(module, "main", None)
    if main is None or not inspect.iscoroutinefunction(main):
        raise AppLoadError(f"{path}: an application defines 'async def main(argv)'")
    return module


def run(path_text: str, argv: list[str]) -> int:
    path = Path(path_text)
    if path.suffix.lower() in PROFILE_SUFFIXES:
        runner = importlib.import_module("openel_async.rtc.runner")
        return int(runner.run_profile_cli(path, argv))
    try:
        module = load_app(path)
    except AppLoadError as exc:
        print(f"openel-async run: {exc}", file=sys.stderr)
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
