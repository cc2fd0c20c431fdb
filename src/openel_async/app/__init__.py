"""The application SDK: what an app implements, what it receives, and how it is run.

An app is user code. It registers an :class:`AppInfo` under the entry-point group
``openel_async.apps`` (or defines ``APP_INFO`` in a file run by path); its ``main`` receives an
:class:`AppContext`: its command line, the name to print its messages under, and the registry of
its clock, components, timers and scene, which are passed on to the :class:`AppHook` objects a
tool attached from outside (a recorder, a live view). :func:`run_app` runs an app to its exit
status, synchronously, as ``openel-async run NAME`` does -- the command line is built on this
module, never the other way round.

Helpers for apps:

- :class:`LiveLine`: a one-line live progress display (periodic lines off a terminal);
- :func:`atomic_output`: write an output file so that it is complete or absent;
- :func:`run_interruptible`: run async work until it returns or SIGINT/SIGTERM stops it
  (:class:`Interrupted`).

docs/apps.md shows how to write, register and test an app. This package imports no driver and
no app: apps are loaded by name when asked for.
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

if TYPE_CHECKING:
    from ._context import (
        ENTRY_POINT_GROUP,
        AppContext,
        AppEntry,
        AppHook,
        AppInfo,
        AppUnavailable,
        DemoOptions,
        discover_apps,
        find_app,
    )
    from ._interrupt import (
        Interrupted,
        atomic_output,
        collect_written,
        note_written,
        run_interruptible,
    )
    from ._progress import LiveLine
    from ._runner import run_app
    from ._signals import (
        EXIT_SIGINT,
        EXIT_SIGTERM,
        exit_code,
        install_sigterm_handler,
        interrupt_code,
    )

# Each name loads its module on first use (a command line's parser imports this package's light modules only).
_LAZY = {
    "ENTRY_POINT_GROUP": "_context",
    "AppContext": "_context",
    "AppEntry": "_context",
    "AppHook": "_context",
    "AppInfo": "_context",
    "AppUnavailable": "_context",
    "DemoOptions": "_context",
    "discover_apps": "_context",
    "find_app": "_context",
    "EXIT_SIGINT": "_signals",
    "EXIT_SIGTERM": "_signals",
    "Interrupted": "_interrupt",
    "atomic_output": "_interrupt",
    "note_written": "_interrupt",
    "collect_written": "_interrupt",
    "exit_code": "_signals",
    "install_sigterm_handler": "_signals",
    "interrupt_code": "_signals",
    "run_interruptible": "_interrupt",
    "LiveLine": "_progress",
    "run_app": "_runner",
}

__getattr__, __dir__ = lazy_exports(__name__, _LAZY)

__all__ = [
    "ENTRY_POINT_GROUP",
    "EXIT_SIGINT",
    "EXIT_SIGTERM",
    "AppContext",
    "AppEntry",
    "AppHook",
    "AppInfo",
    "AppUnavailable",
    "DemoOptions",
    "Interrupted",
    "LiveLine",
    "atomic_output",
    "collect_written",
    "discover_apps",
    "exit_code",
    "find_app",
    "install_sigterm_handler",
    "interrupt_code",
    "note_written",
    "run_app",
    "run_interruptible",
]
