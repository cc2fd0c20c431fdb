"""Connector profiles: OpenRTM's ``dataport.*`` connector properties, checked.

| property | values (case-insensitive) | default |
| --- | --- | --- |
| ``dataport.dataflow_type`` | ``push``, ``pull`` | push |
| ``dataport.subscription_type`` | ``flush``, ``new``, ``periodic`` (push only) | flush |
| ``dataport.interface_type`` | a registered transport (``inprocess``; OpenRTM's ``corba_cdr``, ``direct``, ``data_service``, ``shared_memory`` run in-process) | inprocess |
| ``dataport.data_type`` | an IDL type name; must be the ports' | (the ports') |
| ``dataport.buffer.length`` | integer 1..1 000 000 | 8 |
| ``dataport.buffer.write.full_policy`` | ``overwrite``, ``do_nothing``, ``block`` | overwrite |
| ``dataport.buffer.write.timeout`` | seconds, 0 < t <= 3600 | 1.0 |
| ``dataport.buffer.read.empty_policy`` | ``readback``, ``do_nothing``, ``block`` | readback |
| ``dataport.buffer.read.timeout`` | seconds, 0 < t <= 3600 | 1.0 |
| ``dataport.inport.buffer.*``, ``dataport.outport.buffer.*`` | the same, for one side only | ``dataport.buffer.*`` |
| ``dataport.publisher.push_rate`` (or ``dataport.push_rate``) | Hz, 1e-6..10 000 (periodic) | 1000 |
| ``dataport.publisher.push_policy`` | ``all``, ``fifo``, ``skip``, ``new`` (new, periodic) | new |
| ``dataport.publisher.skip_count`` | integer >= 0 (push_policy skip) | 0 |

Other ``dataport.*`` keys are refused (a typo must not be ignored); keys outside
``dataport.`` (RTSystemEditor's ``POSITION``...) are kept in ``properties`` and unused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import Enum

from ..errors import RTCBadParameterError
from .buffer import BufferOptions, EmptyPolicy, FullPolicy

__all__ = [
    "BUFFER_SIDES",
    "ConnectorProfile",
    "Dataflow",
    "PushPolicy",
    "Subscription",
]

MAX_BUFFER_LENGTH = 1_000_000
MAX_TIMEOUT_S = 3600.0
MIN_PUSH_RATE_HZ = 1e-6
MAX_PUSH_RATE_HZ = 10_000.0


class Dataflow(Enum):
    PUSH = "push"
    PULL = "pull"


class Subscription(Enum):
    FLUSH = "flush"
    NEW = "new"
    PERIODIC = "periodic"


class PushPolicy(Enum):
    ALL = "all"
    FIFO = "fifo"
    SKIP = "skip"
    NEW = "new"


BUFFER_SIDES = ("dataport.buffer.", "dataport.inport.buffer.", "dataport.outport.buffer.")
_BUFFER_KEYS = (
    "length",
    "write.full_policy",
    "write.timeout",
    "read.empty_policy",
    "read.timeout",
)
_SCALAR_KEYS = (
    "dataport.dataflow_type",
    "dataport.subscription_type",
    "dataport.interface_type",
    "dataport.data_type",
    "dataport.publisher.push_rate",
    "dataport.push_rate",
    "dataport.publisher.push_policy",
    "dataport.publisher.skip_count",
)
KNOWN_KEYS = frozenset(_SCALAR_KEYS) | {p + k for p in BUFFER_SIDES for k in _BUFFER_KEYS}


def _choice(key: str, text: str, enum: type[Enum]) -> Enum:
    value = text.strip().lower()
    for member in enum:
        if member.value == value:
            return member
    raise RTCBadParameterError(key, text, "one of " + ", ".join(m.value for m in enum))


def _number(key: str, text: str, low: float, high: float, *, low_open: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    ok = math.isfinite(value) and (value > low if low_open else value >= low) and value <= high
    if not ok:
        bound = f"{low:g} < x" if low_open else f"{low:g} <= x"
        raise RTCBadParameterError(key, text, f"a number, {bound} <= {high:g}")
    return value


def _integer(key: str, text: str, low: int, high: int) -> int:
    try:
        value = int(text.strip())
    except ValueError:
        raise RTCBadParameterError(key, text, f"an integer, {low} <= n <= {high}") from None
    if not low <= value <= high:
        raise RTCBadParameterError(key, text, f"an integer, {low} <= n <= {high}")
    return value


def _text(key: str, value: object) -> str:
    if isinstance(value, bool):
        raise RTCBadParameterError(key, value, "a string or number, not a bool")
    if isinstance(value, str | int | float):
        return str(value)
    raise RTCBadParameterError(key, value, "a string or number")


def _buffer(props: Mapping[str, str], prefix: str, base: BufferOptions) -> BufferOptions:
    opts = base
    if (t := props.get(prefix + "length")) is not None:
        opts = replace(opts, length=_integer(prefix + "length", t, 1, MAX_BUFFER_LENGTH))
    if (t := props.get(prefix + "write.full_policy")) is not None:
        policy = _choice(prefix + "write.full_policy", t, FullPolicy)
        assert isinstance(policy, FullPolicy)
        opts = replace(opts, full_policy=policy)
    if (t := props.get(prefix + "write.timeout")) is not None:
        key = prefix + "write.timeout"
        opts = replace(opts, write_timeout_s=_number(key, t, 0.0, MAX_TIMEOUT_S, low_open=True))
    if (t := props.get(prefix + "read.empty_policy")) is not None:
        policy2 = _choice(prefix + "read.empty_policy", t, EmptyPolicy)
        assert isinstance(policy2, EmptyPolicy)
        opts = replace(opts, empty_policy=policy2)
    if (t := props.get(prefix + "read.timeout")) is not None:
        key = prefix + "read.timeout"
        opts = replace(opts, read_timeout_s=_number(key, t, 0.0, MAX_TIMEOUT_S, low_open=True))
    return opts


@dataclass(frozen=True, slots=True)
class ConnectorProfile:
    """The checked options of one connector; build it with :meth:`from_properties`."""

    name: str = ""
    dataflow: Dataflow = Dataflow.PUSH
    subscription: Subscription = Subscription.FLUSH
    interface_type: str = "inprocess"
    data_type: str | None = None
    in_buffer: BufferOptions = field(default_factory=BufferOptions)
    """The InPort side's buffer (PUSH connectors)."""
    out_buffer: BufferOptions = field(default_factory=BufferOptions)
    """The OutPort side's buffer (NEW/PERIODIC publishers, and PULL connectors)."""
    push_rate_hz: float = 1000.0
    push_policy: PushPolicy = PushPolicy.NEW
    skip_count: int = 0
    properties: Mapping[str, str] = field(default_factory=dict)

    @property
    def blocking(self) -> bool:
        """True when a write or a read on this connector may wait (a block policy)."""
        if self.dataflow is Dataflow.PULL:
            return self.out_buffer.blocking
        if self.subscription is Subscription.FLUSH:
            return self.in_buffer.blocking
        return self.in_buffer.blocking or self.out_buffer.blocking

    @classmethod
    def from_properties(
        cls, properties: Mapping[str, object] | None = None, *, name: str = ""
    ) -> ConnectorProfile:
        """Check and read OpenRTM connector properties (see the module docstring).

        Raises RTCBadParameterError naming the property and what is allowed."""
        raw = dict(properties or {})
        props: dict[str, str] = {}
        for key, value in raw.items():
            if not isinstance(key, str):
                raise RTCBadParameterError("connector property", key, "a string key")
            k = key.strip().lower()
            if k.startswith("dataport.") and k not in KNOWN_KEYS:
                raise RTCBadParameterError(
                    "connector property", key, "one of " + ", ".join(sorted(KNOWN_KEYS))
                )
            props[k if k.startswith("dataport.") else key] = _text(key, value)
        dataflow = Dataflow.PUSH
        if (t := props.get("dataport.dataflow_type")) is not None:
            d = _choice("dataport.dataflow_type", t, Dataflow)
            assert isinstance(d, Dataflow)
            dataflow = d
        subscription = Subscription.FLUSH
        if (t := props.get("dataport.subscription_type")) is not None:
            s = _choice("dataport.subscription_type", t, Subscription)
            assert isinstance(s, Subscription)
            subscription = s
        interface = props.get("dataport.interface_type", "inprocess").strip() or "inprocess"
        base = _buffer(props, "dataport.buffer.", BufferOptions())
        in_buffer = _buffer(props, "dataport.inport.buffer.", base)
        out_buffer = _buffer(props, "dataport.outport.buffer.", base)
        rate = 1000.0
        for key in ("dataport.push_rate", "dataport.publisher.push_rate"):
            if (t := props.get(key)) is not None:
                rate = _number(key, t, MIN_PUSH_RATE_HZ, MAX_PUSH_RATE_HZ, low_open=False)
        policy = PushPolicy.NEW
        if (t := props.get("dataport.publisher.push_policy")) is not None:
            p = _choice("dataport.publisher.push_policy", t, PushPolicy)
            assert isinstance(p, PushPolicy)
            policy = p
        skip = 0
        if (t := props.get("dataport.publisher.skip_count")) is not None:
            skip = _integer("dataport.publisher.skip_count", t, 0, 1_000_000)
        data_type = props.get("dataport.data_type")
        return cls(
            name=name,
            dataflow=dataflow,
            subscription=subscription,
            interface_type=interface,
            data_type=data_type.strip() if data_type is not None else None,
            in_buffer=in_buffer,
            out_buffer=out_buffer,
            push_rate_hz=rate,
            push_policy=policy,
            skip_count=skip,
            properties=props,
        )
