"""MultiModeObject: an RTObject with modes (ModeCapable + MultiModeComponentAction).

Modes are names (``str``) declared by the class (``modes``) or the constructor. The
component keeps the mode last requested with :meth:`MultiModeObject.set_mode`; each
context it participates in keeps the mode it currently sees. A requested mode is
*pending* in a context until the context's next cycle (or at once with
``immediate=True``); the context then takes it and runs ``on_mode_changed`` before
anything else of that cycle. When every context has taken it, the mode has
*stabilized*: it is the current mode and no mode is pending. docs/rtc.md states the
rules in full.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, ClassVar

import anyio

from ..clock import Clock
from .configuration import Configuration
from .errors import PreconditionNotMetError, RTCBadParameterError, RTCError
from .rtobject import CallbackResult, ObjectState, RTObject

if TYPE_CHECKING:
    from .context import ExecutionContext

__all__ = ["MultiModeObject"]


class MultiModeObject(RTObject):
    """An RT component with modes; override :meth:`on_mode_changed` to react."""

    modes: ClassVar[tuple[str, ...]] = ("default",)
    """The modes of the class (the constructor may give others)."""
    default_mode: ClassVar[str | None] = None
    """The mode before any set_mode; None means the first of ``modes``. (When the
    constructor is given modes, its ``default_mode`` or the first of them applies.)"""

    def __init__(
        self,
        instance_name: str = "",
        *,
        modes: Iterable[str] | None = None,
        default_mode: str | None = None,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(instance_name, configuration=configuration, clock=clock)
        names = tuple(modes) if modes is not None else type(self).modes
        if (
            not names
            or not all(isinstance(m, str) and m for m in names)
            or len(set(names)) != len(names)
        ):
            raise RTCBadParameterError("modes", names, "one or more distinct non-empty names")
        default = default_mode
        if default is None and modes is None:
            default = type(self).default_mode  # the class default goes with the class modes
        default = names[0] if default is None else default
        if default not in names:
            raise RTCBadParameterError("default_mode", default, f"one of {names}")
        self._modes = names
        self._default_mode = default
        self._requested = default
        self._stable = default
        self._in_context: dict[ExecutionContext, str] = {}

    # -- ModeCapable -------------------------------------------------------------------
    def get_modes(self) -> tuple[str, ...]:
        """The modes this component can be in."""
        return self._modes

    def get_default_mode(self) -> str:
        """The mode before any set_mode (never None)."""
        return self._default_mode

    def get_current_mode(self) -> str:
        """The last mode to have stabilized (taken by every context); never None."""
        return self._stable

    def get_pending_mode(self) -> str | None:
        """The last requested mode while some context has not taken it yet, else None."""
        return None if self._is_stable() else self._requested

    def get_current_mode_in_context(self, exec_context: ExecutionContext) -> str:
        """The mode ``exec_context`` currently sees (BAD_PARAMETER if not participating)."""
        return self._mode_in(exec_context, "exec_context")

    def get_pending_mode_in_context(self, exec_context: ExecutionContext) -> str | None:
        """The requested mode when ``exec_context`` has not taken it yet, else None."""
        seen = self._mode_in(exec_context, "exec_context")
        return None if seen == self._requested else self._requested

    def mode_of(self, exec_handle: int) -> str:
        """The current mode in the context of a handle (for use inside callbacks)."""
        return self._mode_in(self.get_context(exec_handle), "exec_handle")

    async def set_mode(self, new_mode: str, immediate: bool = False) -> None:
        """Request ``new_mode``.

        It stays pending in each context until that context's next cycle, where the
        context takes it and runs on_mode_changed before on_execute. With ``immediate``
        every context takes it now: on_mode_changed runs in each context as soon as the
        component's callback running there (if any) has returned; called from one of
        the component's own callbacks, the context of that callback takes the mode at
        once and runs on_mode_changed right after the calling callback returns.
        """
        if new_mode not in self._modes:
            raise RTCBadParameterError("new_mode", new_mode, f"one of {self._modes}")
        if not isinstance(immediate, bool):
            raise RTCBadParameterError("immediate", immediate, "a bool")
        if self._state is ObjectState.FINALIZED:
            raise PreconditionNotMetError(
                "set_mode", self._state, [ObjectState.CREATED, ObjectState.ALIVE]
            )
        self._requested = new_mode
        self.log.info("mode_requested", mode=new_mode, immediate=immediate)
        if immediate:
            errors: list[RTCError] = []

            async def change(ec: ExecutionContext) -> None:
                try:
                    await ec._change_mode_now(self)
                except RTCError as exc:
                    errors.append(exc)

            async with anyio.create_task_group() as tg:
                for ec, seen in tuple(self._in_context.items()):
                    if seen != new_mode:
                        tg.start_soon(change, ec)
            if errors:
                raise errors[0]
        self._check_stable()

    # -- MultiModeComponentAction ------------------------------------------------------
    async def on_mode_changed(self, exec_handle: int) -> CallbackResult:
        """The mode seen by the context ``exec_handle`` changed (see mode_of)."""
        return None

    # -- bookkeeping used by contexts ------------------------------------------------------
    def _mode_in(self, exec_context: ExecutionContext, parameter: str) -> str:
        for ec, mode in self._in_context.items():
            if ec is exec_context:
                return mode
        raise RTCBadParameterError(parameter, exec_context, "a context this RTC participates in")

    def _is_stable(self) -> bool:
        requested = self._requested
        return all(mode == requested for mode in self._in_context.values())

    def _check_stable(self) -> None:
        if self._is_stable() and self._stable != self._requested:
            self._stable = self._requested
            self.log.info("mode_stabilized", mode=self._stable)

    def _take_pending_mode(self, ec: ExecutionContext) -> bool:
        """The context takes the requested mode; True when its mode changed."""
        seen = self._in_context.get(ec)
        requested = self._requested
        if seen is None or seen == requested:
            return False
        self._in_context[ec] = requested
        self.log.info("mode_changed", ec=ec.name, old=seen, new=requested)
        self._check_stable()
        return True

    def _context_attached(self, ec: ExecutionContext) -> None:
        # A new context starts in the requested mode: it never saw another one.
        self._in_context[ec] = self._requested
        self._check_stable()

    def _context_detached(self, ec: ExecutionContext) -> None:
        self._in_context.pop(ec, None)
        self._check_stable()
