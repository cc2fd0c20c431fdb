"""What the jog UI needs of a jog session, local or remote (no Textual, no rig).

:class:`~.jogger.Jogger` is the session of a rig opened in this process;
``openel-async jog --remote NAMESPACE`` gets a session over a served rig from a driver,
through the entry-point group :data:`REMOTE_JOG_GROUP` (the Zenoh driver's
``openel_zenoh.jog:REMOTE_JOG``): the framework imports no driver.
"""

from __future__ import annotations

import argparse
from collections import deque
from collections.abc import Callable, Sequence
from contextlib import AbstractAsyncContextManager
from typing import Protocol

from .controls import LogEntry

__all__ = ["REMOTE_JOG_GROUP", "JogRow", "JogSession", "RemoteJogProvider"]

REMOTE_JOG_GROUP = "openel_async.remote_jog"
"""Entry points: a :class:`RemoteJogProvider` each (the first one found is used)."""


class JogRow(Protocol):
    """One component as the UI shows it."""

    @property
    def name(self) -> str: ...
    @property
    def kind(self) -> str: ...
    @property
    def units(self) -> str: ...
    @property
    def values(self) -> tuple[float, ...]: ...
    @property
    def target(self) -> float | None: ...
    @property
    def history(self) -> deque[float]: ...
    @property
    def plotted(self) -> bool: ...
    @property
    def read_error(self) -> str | None: ...
    @property
    def state(self) -> str: ...
    @property
    def limits(self) -> tuple[float, float] | None: ...


class JogSession(Protocol):
    """What :class:`~.app.JogApp` drives (see :class:`~.jogger.Jogger` for each member)."""

    on_log: Callable[[LogEntry], object] | None

    @property
    def rows(self) -> Sequence[JogRow]: ...
    @property
    def row(self) -> JogRow: ...
    @property
    def selected(self) -> int: ...
    @property
    def step(self) -> float: ...
    @property
    def velocity(self) -> float: ...
    @property
    def completed(self) -> int: ...
    @property
    def log(self) -> deque[LogEntry]: ...
    @property
    def title(self) -> str:
        """The UI's subtitle: the rig file, or the namespace and endpoint."""
        ...

    @property
    def estopped(self) -> bool: ...

    def jogs(self, row: JogRow) -> bool:
        """Whether ``row`` is an axis that takes a position (jogged by the arrows)."""
        ...

    def select(self, index: int) -> None: ...
    def change_step(self, delta: int) -> float: ...
    def change_velocity(self, delta: int) -> float: ...
    def toggle_plot(self) -> bool: ...
    def jog(self, direction: int) -> float | None: ...
    async def poll(self) -> None: ...
    async def stop(self) -> None: ...
    async def enable(self) -> None: ...
    async def disable(self) -> None: ...
    async def estop(self) -> None: ...
    async def release(self) -> None: ...


class RemoteJogProvider(Protocol):
    """A driver's remote jog (``openel-async jog --remote NAMESPACE``)."""

    def check(self, args: argparse.Namespace) -> str | None:
        """Why the options cannot be used (checked before anything is opened), or None."""
        ...

    def session(self, args: argparse.Namespace) -> AbstractAsyncContextManager[JogSession]:
        """The jog session over the served rig ``args.remote``; raises HALError (its message
        for the user: no such namespace, which are served...) when there is none."""
        ...


def remote_providers() -> Sequence[RemoteJogProvider]:
    """The installed drivers' remote jogs."""
    from importlib.metadata import entry_points

    found: list[RemoteJogProvider] = [ep.load() for ep in entry_points(group=REMOTE_JOG_GROUP)]
    return found
