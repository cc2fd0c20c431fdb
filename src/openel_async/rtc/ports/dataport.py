"""InPort and OutPort: OpenRTM's data ports over connectors (see :mod:`.connector`).

- ``await out.write(value)`` stamps ``tm`` from the port's clock when the value has none
  (a bare payload, ``await out.write(1.5)``, is converted to the port's type and
  checked), then hands it to every connector; it returns True when all of them took it
  (OpenRTM's ``OutPort::write``); ``out.status`` tells the first failure.
- ``in_.is_new()`` is True while some connector has an unread value; ``await in_.read()``
  returns the oldest unread value of the first connector (in connection order) that has
  one, else what that first connector's empty policy gives (readback: the last value
  again; do_nothing: None; block: waits up to its timeout); ``in_.status`` is the
  PortStatus of the last read, ``in_.value`` the last value read.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Generic, TypeVar

import msgspec

from ...clock import Clock
from ..errors import RTCBadParameterError
from .base import PortBase
from .buffer import ReadOutcome
from .datatypes import NS_PER_S, RTCTime, TimedValue, data_type_name, payload_type, stamp
from .status import PortStatus

if TYPE_CHECKING:
    from .connector import InHalf, OutHalf

__all__ = ["DataPort", "InPort", "OutPort"]

T = TypeVar("T", bound=TimedValue)

_OK = PortStatus.PORT_OK


class DataPort(PortBase, Generic[T]):
    """Common part of InPort and OutPort: the data type and the connectors."""

    def __init__(self, name: str, data_type: type[T], *, clock: Clock | None = None) -> None:
        super().__init__(name, clock=clock)
        if not (isinstance(data_type, type) and issubclass(data_type, TimedValue)):
            raise RTCBadParameterError("data_type", data_type, "a Timed* type of rtc.ports")
        self.data_type: type[T] = data_type
        self.status = PortStatus.PORT_OK
        self.value: T | None = None

    @property
    def type_name(self) -> str:
        """The IDL name, e.g. ``RTC::TimedDouble``."""
        return data_type_name(self.data_type)


class OutPort(DataPort[T]):
    """A data output port."""

    def __init__(self, name: str, data_type: type[T], *, clock: Clock | None = None) -> None:
        super().__init__(name, data_type, clock=clock)
        self.connectors: list[OutHalf] = []
        self.writes = 0
        self._payload_type = payload_type(data_type)
        self._fast = _fast_converter(self._payload_type)

    def convert(self, value: object) -> T:
        """``value`` as the port's type, stamped with the port clock's time when it has
        no ``tm``: an instance as is, a payload converted and checked (BAD_PARAMETER
        naming the port otherwise)."""
        data_type = self.data_type
        if type(value) is data_type:
            if value.tm is None:
                return stamp(value, self.clock.now_ns())  # type: ignore[return-value]
            return value
        payload = self._fast(value)  # None for anything but plain numbers and sequences
        if payload is None:
            if isinstance(value, TimedValue):
                raise RTCBadParameterError(
                    f"{self.full_name}.write", value, f"a {self.type_name} or its payload"
                )
            try:
                payload = msgspec.convert(value, self._payload_type)
            except msgspec.ValidationError as exc:
                raise RTCBadParameterError(
                    f"{self.full_name}.write", value, f"a {self.type_name} payload ({exc})"
                ) from None
        sec, nsec = divmod(self.clock.now_ns(), NS_PER_S)
        return data_type(RTCTime(sec, nsec), payload)  # type: ignore[call-arg]

    async def write(self, value: T | object) -> bool:
        """Send ``value`` on every connector; True when all took it."""
        payload = self._fast(value)  # the common payloads, checked without a call more
        if payload is None:
            data = self.convert(value)
        else:
            sec, nsec = divmod(self.clock.now_ns(), NS_PER_S)
            data = self.data_type(RTCTime(sec, nsec), payload)  # type: ignore[call-arg]
        self.value = data
        self.writes += 1
        connectors = self.connectors
        if len(connectors) == 1:
            half = connectors[0]
            status = half.offer(data)
            if status is None:  # it has to wait or call listeners
                status = await half.write(data)
        elif not connectors:
            self.status = PortStatus.PRECONDITION_NOT_MET
            return False
        else:
            status = _OK
            for half in connectors:
                result = half.offer(data)
                if result is None:
                    result = await half.write(data)
                if result is not _OK and status is _OK:
                    status = result
        self.status = status
        return status is _OK


def _is_number(x: object) -> bool:
    return type(x) is float or (type(x) is int and -(2**53) <= x <= 2**53)


def _float_payload(value: object) -> float | None:
    return float(value) if _is_number(value) else None  # type: ignore[arg-type]


def _float_seq_payload(value: object) -> tuple[float, ...] | None:
    kind = type(value)
    if kind is not tuple and kind is not list:
        return None
    items: tuple[object, ...] | list[object] = value  # type: ignore[assignment]
    for x in items:
        if type(x) is not float:
            break
    else:  # all floats: the common case
        return items if kind is tuple else tuple(items)  # type: ignore[return-value,arg-type]
    for x in items:
        if not _is_number(x):
            return None
    return tuple(map(float, items))  # type: ignore[arg-type]


def _fast_converter(payload: object) -> Callable[[object], object | None]:
    """A quick check-and-convert for the common payloads (doubles and sequences of
    them); anything else (None) goes through msgspec.convert."""
    if payload is float:
        return _float_payload
    if payload == tuple[float, ...]:
        return _float_seq_payload
    return lambda value: None


class InPort(DataPort[T]):
    """A data input port."""

    def __init__(self, name: str, data_type: type[T], *, clock: Clock | None = None) -> None:
        super().__init__(name, data_type, clock=clock)
        self.connectors: list[InHalf] = []

    def is_new(self) -> bool:
        """True while a connector holds an unread value."""
        connectors = self.connectors
        if len(connectors) == 1:
            return connectors[0].readable() > 0
        return any(half.readable() > 0 for half in connectors)

    def is_empty(self) -> bool:
        return not self.is_new()

    def readable(self) -> int:
        """Unread values over all connectors."""
        return sum(half.readable() for half in self.connectors)

    async def read(self) -> T | None:
        """The next value (see the module docstring); None when nothing could be read,
        ``status`` then says why (BUFFER_EMPTY, BUFFER_TIMEOUT, PRECONDITION_NOT_MET
        without connectors)."""
        connectors = self.connectors
        if not connectors:
            self.status = PortStatus.PRECONDITION_NOT_MET
            return None
        chosen = connectors[0]
        if len(connectors) > 1 and chosen.readable() == 0:
            for half in connectors:
                if half.readable() > 0:
                    chosen = half
                    break
        value = chosen.poll()
        if value is not None:  # an unread value and no listener: no policy to apply
            self.status = _OK
            self.value = value  # type: ignore[assignment]
            return value  # type: ignore[return-value]
        status, outcome, value = await chosen.read()
        self.status = status
        if outcome is ReadOutcome.NONE:
            return None
        self.value = value  # type: ignore[assignment]
        return value  # type: ignore[return-value]
