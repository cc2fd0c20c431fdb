"""The openel-async pytest plugin (registered through the ``pytest11`` entry point).

Any project that installs openel-async gets these fixtures:

- ``virtual_clock``: a :class:`VirtualClock` with auto-jump running;
- ``hal_components``: enters any component you build, on the virtual clock, in a task
  of its own (so the test's cancel scopes never interleave with it), and finalizes it at
  the end of the test;
- ``hal_events``: an :class:`EventRecorder`.

The simulated devices (``sim_motor``, ``sim_actuator``, ``sim_encoder``, ``sim_imu``) come
from the ``openel_sim`` driver's own plugin (:mod:`openel_sim.pytest_plugin`, also under
``pytest11``), built on these fixtures: this module imports no driver.

Async tests run on anyio's pytest plugin pinned to the asyncio backend; coroutine
tests without an explicit marker are marked ``anyio`` automatically.
"""

from __future__ import annotations

import inspect
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any, TypeVar

import anyio
import anyio.abc
import pytest

from .actuator import Actuator
from .clock import Clock, VirtualClock
from .component import HALComponent
from .sensor import Sensor

C = TypeVar("C", bound=HALComponent)


@dataclass(frozen=True, slots=True)
class Record:
    """One notification with the clock time it arrived at."""

    kind: str
    """'event', 'error' or 'timer'."""
    source: object
    id: int
    time_ns: int


class EventRecorder:
    """A HALObserver and TimerObserver that keeps every notification with its time."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.records: list[Record] = []
        self._changed = anyio.Event()

    def _add(self, kind: str, source: object, ident: int) -> None:
        self.records.append(Record(kind, source, ident, self.clock.now_ns()))
        self._changed.set()
        self._changed = anyio.Event()

    def notify_event(self, source: object, event_id: int) -> None:
        self._add("event", source, int(event_id))

    def notify_error(self, source: object, error_id: int) -> None:
        self._add("error", source, int(error_id))

    def notify_timer(self, timer: Any) -> None:
        tick = timer.last_tick
        self._add("timer", timer, tick.index if tick is not None else 0)

    @property
    def events(self) -> list[Record]:
        return [r for r in self.records if r.kind == "event"]

    @property
    def errors(self) -> list[Record]:
        return [r for r in self.records if r.kind == "error"]

    def count(self, kind: str = "event", ident: int | None = None, source: object = None) -> int:
        return sum(
            1
            for r in self.records
            if r.kind == kind
            and (ident is None or r.id == ident)
            and (source is None or r.source is source)
        )

    async def wait_for(
        self,
        kind: str = "event",
        ident: int | None = None,
        *,
        source: object = None,
        count: int = 1,
        timeout: float = 10.0,  # noqa: ASYNC109 - a bound in real seconds for tests
    ) -> Record:
        """Wait (bounded by ``timeout`` real seconds) until ``count`` matching records exist."""
        with anyio.fail_after(timeout):
            while True:
                matching = [
                    r
                    for r in self.records
                    if r.kind == kind
                    and (ident is None or r.id == ident)
                    and (source is None or r.source is source)
                ]
                if len(matching) >= count:
                    return matching[count - 1]
                await self._changed.wait()

    def clear(self) -> None:
        self.records.clear()


class ComponentStack:
    """Enters components for a test and exits them (finalize) in reverse order.

    Each component lives in a task of its own in the fixture's task group: its
    ``__aenter__`` and ``__aexit__`` (and the task group it opens) run there, never in
    the test's task, so the test's cancel scopes (``anyio.fail_after``, ``move_on_after``)
    and the component's lifetime never interleave. Entering still belongs to the caller:
    until the component is entered, cancelling the caller (a ``fail_after`` expiring)
    cancels the entering, and an error from ``__aenter__`` is raised to the caller.
    """

    def __init__(self, task_group: anyio.abc.TaskGroup, clock: VirtualClock) -> None:
        self._task_group = task_group
        self._hosts: list[tuple[anyio.Event, anyio.Event]] = []
        self.clock = clock

    async def enter(self, component: C) -> C:
        stop = anyio.Event()
        done = anyio.Event()
        await self._task_group.start(_host, component, stop, done)
        self._hosts.append((stop, done))
        return component

    async def actuator(self, device: Any, **kwargs: Any) -> Actuator:
        kwargs.setdefault("clock", self.clock)
        return await self.enter(Actuator(device, **kwargs))

    async def sensor(self, device: Any, **kwargs: Any) -> Sensor:
        kwargs.setdefault("clock", self.clock)
        return await self.enter(Sensor(device, **kwargs))

    async def aclose(self) -> None:
        """Exit every component, last entered first, each after the one entered after it."""
        while self._hosts:
            stop, done = self._hosts.pop()
            stop.set()
            await done.wait()


async def _host(
    component: HALComponent,
    stop: anyio.Event,
    done: anyio.Event,
    *,
    task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
) -> None:
    """Hold ``component`` entered, in this task, until ``stop`` is set."""
    try:
        async with component:
            task_status.started()
            await stop.wait()
    finally:
        done.set()


@pytest.fixture
def anyio_backend() -> str:
    """openel-async runs on anyio's asyncio backend."""
    return "asyncio"


@pytest.fixture
async def virtual_clock() -> AsyncIterator[VirtualClock]:
    clock = VirtualClock()
    async with clock.autojump():
        yield clock


@pytest.fixture
def hal_events(virtual_clock: VirtualClock) -> EventRecorder:
    return EventRecorder(virtual_clock)


@pytest.fixture
async def hal_components(virtual_clock: VirtualClock) -> AsyncIterator[ComponentStack]:
    async with anyio.create_task_group() as task_group:
        components = ComponentStack(task_group, virtual_clock)
        try:
            yield components
        finally:
            await components.aclose()


def pytest_pycollect_makeitem(
    collector: pytest.Module | pytest.Class, name: str, obj: object
) -> None:
    """Mark coroutine tests ``anyio`` (on the pinned asyncio backend) unless marked otherwise.

    Done at collection, before parametrization, as anyio's own plugin expects.
    """
    if not collector.istestfunction(obj, name):
        return
    inner: Any = getattr(getattr(obj, "hypothesis", None), "inner_test", obj)
    if not inspect.iscoroutinefunction(inner):
        return
    marks = [m.name for m in getattr(obj, "pytestmark", ())]
    if any(collector.iter_markers("asyncio")) or {"asyncio", "trio"} & set(marks):
        return
    if "anyio" not in marks and collector.get_closest_marker("anyio") is None:
        pytest.mark.anyio(obj)
    pytest.mark.usefixtures("anyio_backend")(obj)
