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
    EXIT_SIGINT,
    EXIT_SIGTERM,
    Interrupted,
    atomic_output,
    collect_written,
    exit_code,
    install_sigterm_handler,
    interrupt_code,
    run_interruptible,
)
from ._progress import LiveLine
from ._runner import run_app

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
    "run_app",
    "run_interruptible",
]
