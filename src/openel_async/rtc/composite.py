"""Composite components: an RTC that contains RTCs and shares its context with them.

The RTC specification (LightweightRTObject::exit) says of contained RTCs: members that
participate in contexts owned by the RTC containing them are deactivated there when it
exits, and "it and any RTCs contained transitively within it shall be finalized". The
rest follows OpenRTM-aist's ``PeriodicECSharedComposite``:

- a member joins every context the composite owns and participates in, right after the
  composite (so each cycle runs the composite, then its members, in the order added);
- activating, deactivating the composite there does the same to its members (after
  the composite's own callback); removing the composite removes them first;
- :meth:`CompositeRTObject.exit` stops the composite's contexts, deactivates and
  removes its members there, exits the composite, then exits every member
  (transitively: a member that is a composite exits its own members).

A component is the member of at most one composite, never of itself or of a composite
it contains.
"""

from __future__ import annotations

from typing import TYPE_CHECKING
from weakref import WeakKeyDictionary

from ..clock import Clock
from .configuration import Configuration
from .errors import CallbackFailedError, PreconditionNotMetError, RTCBadParameterError
from .rtobject import ObjectState, RTObject

if TYPE_CHECKING:
    from .context import ExecutionContext

__all__ = ["CompositeRTObject", "composite_of"]

_container: WeakKeyDictionary[RTObject, CompositeRTObject] = WeakKeyDictionary()


def composite_of(rtc: RTObject) -> CompositeRTObject | None:
    """The composite containing ``rtc``, if any."""
    return _container.get(rtc)


class CompositeRTObject(RTObject):
    """An RTC containing member RTCs that run in its context (see the module docs)."""

    def __init__(
        self,
        instance_name: str = "",
        *,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(instance_name, configuration=configuration, clock=clock)
        self._members: list[RTObject] = []

    @property
    def members(self) -> tuple[RTObject, ...]:
        return tuple(self._members)

    def _shared(self) -> list[ExecutionContext]:
        return [ec for ec in self.get_owned_contexts() if ec in self.get_participating_contexts()]

    async def add_member(self, rtc: RTObject) -> None:
        """Contain ``rtc`` (Alive): it joins the composite's contexts, Active where the
        composite is. BAD_PARAMETER for a non-RTC, itself or a containing composite;
        PRECONDITION_NOT_MET when it is not Alive or already a member somewhere."""
        from .context import LifeCycleState

        if not isinstance(rtc, RTObject):
            raise RTCBadParameterError("rtc", rtc, "an RTObject")
        ancestor: RTObject | None = self
        while ancestor is not None:
            if ancestor is rtc:
                raise RTCBadParameterError(
                    "rtc", rtc.instance_name, "a component that does not contain this composite"
                )
            ancestor = _container.get(ancestor)
        owner = _container.get(rtc)
        if owner is not None:
            raise PreconditionNotMetError(
                "add_member", f"member of {owner.instance_name}", "a component of no composite"
            )
        if rtc.state is not ObjectState.ALIVE:
            raise PreconditionNotMetError("add_member", rtc.state, [ObjectState.ALIVE])
        _container[rtc] = self
        self._members.append(rtc)
        self.log.info("member_added", member=rtc.instance_name)
        for ec in self._shared():
            await ec.add_component(rtc)
            if ec.get_component_state(self) is LifeCycleState.ACTIVE:
                await ec.activate_component(rtc)

    async def remove_member(self, rtc: RTObject) -> None:
        """Stop containing ``rtc``: it leaves the composite's contexts (deactivated
        first). BAD_PARAMETER when it is not a member."""
        if rtc not in self._members:
            raise RTCBadParameterError(
                "rtc",
                rtc,
                f"a member of {self.instance_name}: {[m.instance_name for m in self._members]}",
            )
        await self._leave(rtc, self._shared())
        self._members.remove(rtc)
        del _container[rtc]
        self.log.info("member_removed", member=rtc.instance_name)

    async def _leave(self, rtc: RTObject, contexts: list[ExecutionContext]) -> None:
        from .context import LifeCycleState

        for ec in contexts:
            if rtc not in ec.participants:
                continue
            if ec.get_component_state(rtc) is LifeCycleState.ACTIVE:
                try:
                    await ec.deactivate_component(rtc)
                except CallbackFailedError as exc:
                    self.log.warning(
                        "member_deactivate_failed", member=rtc.instance_name, error=str(exc)
                    )
            await ec.remove_component(rtc)

    async def _shared_context_event(self, ec: ExecutionContext, event: str) -> None:
        if ec.owner is not self:
            return
        from .context import LifeCycleState

        for rtc in tuple(self._members):
            joined = rtc in ec.participants
            if event == "add" and not joined and rtc.state is ObjectState.ALIVE:
                await ec.add_component(rtc)
            elif event == "remove" and joined:
                await self._leave(rtc, [ec])
            elif event in ("activate", "deactivate") and joined:
                state = ec.get_component_state(rtc)
                if event == "activate" and state is LifeCycleState.INACTIVE:
                    await ec.activate_component(rtc)
                elif event == "deactivate" and state is LifeCycleState.ACTIVE:
                    await ec.deactivate_component(rtc)

    async def exit(self) -> None:
        """Stop the owned contexts, take the members out of them, exit the composite,
        then exit every member that is still Alive (transitively)."""
        if self.state is not ObjectState.ALIVE:
            raise PreconditionNotMetError("exit", self.state, [ObjectState.ALIVE])
        for ec in self.get_owned_contexts():
            if ec.is_running():
                await ec.stop()
        for rtc in tuple(self._members):
            await self._leave(rtc, list(self.get_owned_contexts()))
        try:
            await super().exit()
        finally:
            for rtc in tuple(self._members):
                if rtc.state is ObjectState.ALIVE:
                    await rtc.exit()
