"""Applications of the ``openel-async`` command: the interface an app implements, its discovery
through the ``openel_async.apps`` entry-point group, and the runner of ``openel-async run NAME``
and ``openel-async demo``.

An app package registers an :class:`AppInfo` under the entry-point group, exactly as a driver
registers its ``DriverInfo``::

    [project.entry-points."openel_async.apps"]
    arm2 = "openel_apps.arm2_square:APP"

The app's ``main`` receives an :class:`AppContext`: its command line (``ctx.argv``), the name to
print its messages under (``ctx.prog``), and the registry of what it runs -- the clock
(:meth:`AppContext.use_clock`), its HAL components (:meth:`AppContext.add_component`) and
timers (:meth:`AppContext.add_timer`). Every registration is passed on to the context's
:class:`AppHook` objects, so a tool attached from the command line (a recorder, a live view)
observes any app's components and timers without the app knowing it. docs/apps.md shows how
to write one.

This module imports no driver and no app: apps are loaded by name when asked for.
"""

from __future__ import annotations

import argparse
from collections.abc import AsyncIterator, Awaitable, Callable, Collection, Iterable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, TypeVar

from openel_async.logs import get_logger

from ..entrypoints import entry_points
from ..errors import BadParameterError

if TYPE_CHECKING:
    from ..clock import Clock
    from ..component import HALComponent
    from ..rig import ResolvedRig, Rig
    from ..timer import EventTimer

__all__ = [
    "ENTRY_POINT_GROUP",
    "AppContext",
    "AppEntry",
    "AppHook",
    "AppInfo",
    "AppUnavailable",
    "DemoOptions",
    "discover_apps",
    "find_app",
]

log = get_logger(__name__)

ENTRY_POINT_GROUP = "openel_async.apps"

C = TypeVar("C", bound="HALComponent")
K = TypeVar("K", bound="Clock")


class AppUnavailable(Exception):
    """Raised by an app's ``main`` before it does anything when what it needs cannot load
    (e.g. MuJoCo or its model): ``openel-async demo`` then falls back to another app unless
    the app was asked for by name."""

    def __init__(self, needs: str, reason: str) -> None:
        super().__init__(f"{needs} is unavailable: {reason}")
        self.needs = needs
        """What could not load, e.g. ``"MuJoCo"``."""
        self.reason = reason


@dataclass(frozen=True, slots=True)
class DemoOptions:
    """The options of ``openel-async demo``, for an app's :attr:`AppInfo.demo_args`
    (None: not given on the command line)."""

    bus: str | None = None
    duration: float | None = None
    period_ms: float | None = None
    virtual: bool = False
    inject_fault: bool = False
    live: bool = True
    out: str | None = None


class AppHook:
    """Something attached to a run from outside the app (e.g. a recorder): it is entered
    around the app's ``main`` (an async context manager: its own tasks live in that block) and
    told of each clock, component and timer the app registers. Every method is optional: this
    base class does nothing. A hook must not block: it runs in the app's task."""

    async def __aenter__(self) -> AppHook:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        return None

    def clock_set(self, ctx: AppContext, clock: Clock) -> None:
        """The app runs on ``clock`` (components and timers share it)."""

    def component_added(self, ctx: AppContext, component: HALComponent) -> None:
        """The app registered ``component``, before entering it (``async with``): an observer
        added now sees every notice of its life."""

    def timer_added(self, ctx: AppContext, timer: EventTimer) -> None:
        """The app registered ``timer``, before starting it."""

    def scene_added(self, ctx: AppContext, source: object) -> None:
        """The app handed over a 3D scene (an ``openel_async.recording.SceneSource``, e.g.
        ``openel_mujoco.foxglove_scene.MujocoScene``: its bodies' poses and geometry)."""


class AppContext:
    """What an app's ``main`` receives: its command line, the name to print its messages
    under, and the registry of its clock, components and timers (passed on to the hooks)."""

    def __init__(
        self,
        argv: Sequence[str] = (),
        *,
        prog: str = "app",
        hooks: Iterable[AppHook] = (),
        rig: ResolvedRig | None = None,
        sim: bool = False,
    ) -> None:
        self.argv: list[str] = list(argv)
        self.rig_spec: ResolvedRig | None = rig
        """The rig of ``--rig FILE`` (checked against the drivers before the app runs), or
        None: :meth:`open_rig` opens the app's own default."""
        self.sim = sim
        """``--sim``: the rig runs against simulated peers on simulated buses."""
        self.rigs: list[Rig] = []
        """The rigs the app opened (:meth:`open_rig`), kept after they closed for the
        summary (:attr:`Rig.exit_report`)."""
        self.prog = prog
        """``openel-async demo``, ``openel-async run NAME`` or the app's own name."""
        self.hooks: list[AppHook] = list(hooks)
        self.clock: Clock | None = None
        self.components: list[HALComponent] = []
        self.timers: list[EventTimer] = []
        self.title = ""
        """What the summary of an interrupted run is called (the app sets it)."""
        self.progress: Callable[[], list[str]] | None = None
        """Lines saying what the run did so far, printed when a signal stops it."""

    def use_clock(self, clock: K) -> K:
        """Register the clock the app runs on; returns it."""
        self.clock = clock
        for hook in self.hooks:
            hook.clock_set(self, clock)
        return clock

    def add_component(self, component: C) -> C:
        """Register a HAL component (before entering it); returns it."""
        self.components.append(component)
        for hook in self.hooks:
            hook.component_added(self, component)
        return component

    def add_timer(self, timer: EventTimer) -> EventTimer:
        """Register an EventTimer (before starting it); returns it."""
        self.timers.append(timer)
        for hook in self.hooks:
            hook.timer_added(self, timer)
        return timer

    @property
    def rig(self) -> Rig:
        """The rig the app opened last (:meth:`open_rig`)."""
        if not self.rigs:
            raise RuntimeError("no rig opened: use 'async with ctx.open_rig(...)' first")
        return self.rigs[-1]

    @asynccontextmanager
    async def open_rig(
        self,
        default: str | Path | None = None,
        *,
        clock: Clock | None = None,
        sim: bool | None = None,
        init: bool = True,
    ) -> AsyncIterator[Rig]:
        """Open the rig of ``--rig FILE`` (else ``default``, the app's own rig file) with
        ``--sim`` (``sim`` overrides it: an app's default rig may always be simulated), its
        clock ``clock`` (default: :attr:`clock`); its components and timers are registered
        (the hooks see them), SIGQUIT e-stops it, and at exit every actuator is left as its
        ``safety.on_exit`` says. BadParameterError for a default rig file that is wrong."""
        from ..rig import load_rig, open_rig, resolve_rig

        spec = self.rig_spec
        if spec is None:
            if default is None:
                raise BadParameterError("rig", None, "a rig file: give --rig FILE")
            spec = resolve_rig(load_rig(default))
        async with open_rig(
            spec,
            clock if clock is not None else self.clock,
            sim=self.sim if sim is None else sim,
            init=init,
            on_component=self.add_component,
            on_timer=self.add_timer,
            handle_sigquit=True,
        ) as rig:
            self.rigs.append(rig)
            yield rig

    def add_scene(self, source: object) -> None:
        """Hand a 3D scene of the rig over to the hooks (the live view draws it)."""
        for hook in self.hooks:
            hook.scene_added(self, source)


@dataclass(frozen=True)
class AppInfo:
    """What an app package registers under ``openel_async.apps``.

    Either ``main`` (``async def main(ctx: AppContext) -> int | None``: the exit status) or
    ``profile`` (an RTC Profile shipped with the app, run as ``openel-async run PROFILE``).
    ``demo_args`` makes the app runnable by ``openel-async demo --app NAME``: it turns the
    demo's options into the app's command line, raising ``ValueError`` (the message for the
    user) for an option the app cannot honour."""

    name: str
    description: str
    """One line, for ``openel-async demo --list``."""
    main: Callable[[AppContext], Awaitable[int | None]] | None = None
    profile: Path | None = None
    demo_args: Callable[[DemoOptions], list[str]] | None = field(default=None, repr=False)
    takes_rig: bool = False
    """The app opens its hardware with :meth:`AppContext.open_rig` (a profile app: from its
    configuration parameters ``rig`` and ``sim``): ``--rig FILE`` and ``--sim`` are allowed
    (refused for any other app)."""
    parser: Callable[[str], argparse.ArgumentParser] | None = field(default=None, repr=False)
    """The app's argument parser, given its ``prog`` (the one ``main`` parses
    :attr:`AppContext.argv` with): ``run`` answers ``--help`` and refuses a mistaken option
    with it before the event loop starts, so that they cost no loop start-up."""

    def __post_init__(self) -> None:
        if (self.main is None) == (self.profile is None):
            raise ValueError(f"app {self.name!r}: give exactly one of main and profile")


@dataclass(frozen=True)
class AppEntry:
    name: str
    value: str
    info: AppInfo | None
    error: str | None = None


def discover_apps(names: Collection[str] | None = None) -> list[AppEntry]:
    """Load every registered app (``names``: only those); an app that fails to load is
    reported, not raised."""
    found: list[AppEntry] = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if names is not None and ep.name not in names:
            continue
        try:
            info = ep.load()
        except Exception as exc:  # a broken app must not hide the others
            log.warning("app_load_failed", app=ep.name, error=repr(exc))
            found.append(AppEntry(ep.name, ep.value, None, f"{type(exc).__name__}: {exc}"))
            continue
        if not isinstance(info, AppInfo):
            found.append(AppEntry(ep.name, ep.value, None, "entry point is not an AppInfo"))
            continue
        found.append(AppEntry(ep.name, ep.value, info))
    return found


def find_app(name: str) -> AppInfo:
    """The registered app ``name``; raises LookupError saying which names exist."""
    entries = {e.name: e for e in discover_apps({name})}  # the others are not imported
    entry = entries.get(name)
    if entry is None:
        registered = sorted({ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)})
        known = ", ".join(registered) or "none"
        raise LookupError(f"no app named {name!r} (registered: {known})")
    if entry.info is None:
        raise LookupError(f"app {name!r} ({entry.value}) cannot load: {entry.error}")
    return entry.info
