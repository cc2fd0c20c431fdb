"""Recording components for the RTC runtime tests."""

from __future__ import annotations

from dataclasses import dataclass

from openel_async import Clock
from openel_async.rtc import CallbackResult, MultiModeObject, ReturnCode_t, RTObject

MS = 1_000_000

Failure = ReturnCode_t | BaseException | type[BaseException]


@dataclass(frozen=True, slots=True)
class Call:
    time_ns: int
    component: str
    callback: str
    handle: int | None
    mode: str | None = None

    def __str__(self) -> str:
        return f"{self.component}.{self.callback}"


class Journal:
    """Every callback of every recording component, in call order."""

    def __init__(self) -> None:
        self.calls: list[Call] = []

    def names(self, component: str | None = None, *, since: int = 0) -> list[str]:
        return [
            str(c) if component is None else c.callback
            for c in self.calls[since:]
            if component is None or c.component == component
        ]

    def of(self, component: str, callback: str) -> list[Call]:
        return [c for c in self.calls if c.component == component and c.callback == callback]

    def mark(self) -> int:
        return len(self.calls)


class _Recording:
    """Mixin: record each callback, then wait ``delays[name]`` ns, then fail as told."""

    instance_name: str
    clock: Clock

    def _setup(self, journal: Journal) -> None:
        self.journal = journal
        self.fail: dict[str, Failure] = {}
        self.delays: dict[str, int] = {}

    def _mode(self, handle: int | None) -> str | None:
        return None

    async def _record(self, callback: str, handle: int | None = None) -> CallbackResult:
        self.journal.calls.append(
            Call(self.clock.now_ns(), self.instance_name, callback, handle, self._mode(handle))
        )
        delay = self.delays.get(callback)
        if delay:
            await self.clock.sleep_until(self.clock.now_ns() + delay)
        failure = self.fail.get(callback)
        if failure is None:
            return None
        if isinstance(failure, ReturnCode_t):
            return failure
        raise failure

    async def on_initialize(self) -> CallbackResult:
        return await self._record("on_initialize")

    async def on_finalize(self) -> CallbackResult:
        return await self._record("on_finalize")

    async def on_startup(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_startup", exec_handle)

    async def on_shutdown(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_shutdown", exec_handle)

    async def on_activated(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_activated", exec_handle)

    async def on_deactivated(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_deactivated", exec_handle)

    async def on_aborting(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_aborting", exec_handle)

    async def on_error(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_error", exec_handle)

    async def on_reset(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_reset", exec_handle)

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_execute", exec_handle)

    async def on_state_update(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_state_update", exec_handle)

    async def on_rate_changed(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_rate_changed", exec_handle)


class Recorder(_Recording, RTObject):
    """A data flow component that records its callbacks."""

    def __init__(self, name: str, journal: Journal, clock: Clock) -> None:
        RTObject.__init__(self, name, clock=clock)
        self._setup(journal)


class ModalRecorder(_Recording, MultiModeObject):
    """A multi-mode component that records its callbacks and the mode each one saw."""

    modes = ("normal", "safe", "fast")

    def __init__(self, name: str, journal: Journal, clock: Clock) -> None:
        MultiModeObject.__init__(self, name, clock=clock)
        self._setup(journal)

    def _mode(self, handle: int | None) -> str | None:
        if handle is None:
            return None
        try:
            return self.mode_of(handle)
        except Exception:
            return None

    async def on_mode_changed(self, exec_handle: int) -> CallbackResult:
        return await self._record("on_mode_changed", exec_handle)
