"""Payloads of the Zenoh transport other than HAL4RT messages (MessagePack, msgspec); the
specification, field by field with examples, is docs/wire.md.

``execute`` carries a HAL4RT ``Device`` message, as XML (the standard PSM; a payload
starting with '<') or compact MessagePack; the reply uses the request's encoding. The
other queryables and the notice stream use the structures below.

``rig/estop`` and ``rig/estop/release`` (``openel-async serve``) take an empty payload and
reply with an :class:`EstopReply`: the return code of the e-stop (or release) and the state
of every component of the rig after it.
"""

from __future__ import annotations

from collections.abc import Sequence

import msgspec

from openel_async.surface.messages import ResultList

PROTOCOL_VERSION = 1
"""The version of the wire protocol (docs/wire.md): in every ``components`` reply; a client
that sends its own in the ``components`` query is refused when they differ."""


class SubscribeRequest(msgspec.Struct, array_like=True):
    device_kind: str
    event_type: str
    exclude: tuple[str, ...] = ()
    """Event types not delivered (an optional third item, left out when empty: a
    version-1 server that predates it ignores it and delivers them, so a client ignores
    them too); encode with :func:`subscribe_payload`."""


def subscribe_payload(device_kind: str, event_type: str, exclude: Sequence[str] = ()) -> bytes:
    """A SubscribeRequest's bytes, two items when nothing is excluded (as before ``exclude``)."""
    if exclude:
        return encoder.encode((device_kind, event_type, list(exclude)))
    return encoder.encode((device_kind, event_type))


class Answer(msgspec.Struct, array_like=True):
    """A reply of the small queryables: return_code (0 = HAL_OK), message, and a value."""

    return_code: int
    message: str = ""
    subscribe_id: int = 0
    detail: ResultList | None = None


class ComponentInfo(msgspec.Struct, array_like=True):
    device_kind: str
    logical_id: int
    device_name: str
    state: str


class ComponentsReply(msgspec.Struct, array_like=True):
    """The reply of ``surface/components``: the server's protocol version and its components."""

    protocol: int
    components: list[ComponentInfo]


class RigComponentState(msgspec.Struct, array_like=True):
    """One component of a served rig, after an e-stop or its release."""

    name: str
    state: str
    """``Error``, ``Active``...: the component's state (ComponentState's value)."""
    error_id: int
    """The error id of its last fault while in Error (``ErrorId.ESTOP`` = 8 after an
    e-stop of an operating component), else 0."""
    latched: bool
    """The e-stop is latched: ``re_init`` is refused until it is released."""


class EstopReply(msgspec.Struct, array_like=True):
    """The reply of ``rig/estop`` and ``rig/estop/release``: return_code 0 (HAL_OK) when
    every component was e-stopped (released), else the first failure's code and message
    (every component was tried); ``components`` in the rig file's order."""

    return_code: int
    message: str
    release: bool
    components: list[RigComponentState]


class LifecycleRequest(msgspec.Struct, array_like=True):
    """A query of ``rig/lifecycle``: ``action`` is ``get``, ``activate``, ``deactivate`` or
    ``reset``; ``names``: the components (rig names; empty: every one, ``get`` only)."""

    action: str
    names: list[str] = []


class LifecycleComponent(msgspec.Struct, array_like=True):
    """One served component's RTC lifecycle state (``ACTIVE``, ``INACTIVE``, ``ERROR``) and
    its HAL state (``Active``, ``Error``...)."""

    name: str
    state: str
    hal_state: str
    latched: bool = False
    """The rig's e-stop is latched (``reset`` is refused until it is released)."""


class LifecycleReply(msgspec.Struct, array_like=True):
    """The reply of ``rig/lifecycle``: return_code 0 (HAL_OK) when the action was done on
    every component named, else the first failure's code and message; ``components``: the
    states after it."""

    return_code: int
    message: str
    components: list[LifecycleComponent]


class ConfRequest(msgspec.Struct, array_like=True):
    """A query of ``rig/conf``: ``value`` None reads (``parameter`` empty: every one),
    else sets ``parameter`` of the set ``set_name`` to the text ``value``."""

    name: str
    set_name: str = "default"
    parameter: str = ""
    value: str | None = None


class ConfParameter(msgspec.Struct, array_like=True):
    name: str
    type: str
    constraint: str
    """OpenRTM's text form of the RTC constraint (empty: none)."""
    unit: str


class ConfSet(msgspec.Struct, array_like=True):
    name: str
    values: dict[str, str]


class ConfReply(msgspec.Struct, array_like=True):
    """The reply of ``rig/conf``: return_code, message (a refusal names the constraint),
    the component's parameters, active set and sets (after a set, its new values)."""

    return_code: int
    message: str
    name: str = ""
    parameters: list[ConfParameter] = []
    active_set: str = ""
    sets: list[ConfSet] = []
    constraint: str = ""
    """The constraint a refused value violates (empty otherwise)."""


class CompletedNotice(msgspec.Struct, array_like=True, tag="C"):
    command_id: str
    status: int


class EventNotice(msgspec.Struct, array_like=True, tag="E"):
    event_id: str
    event_type: str
    subscribe_id: int
    detail: ResultList


class ErrorNotice(msgspec.Struct, array_like=True, tag="R"):
    error_id: str
    error_type: str
    detail: ResultList


Notice = CompletedNotice | EventNotice | ErrorNotice


class NoticeBatch(msgspec.Struct, array_like=True):
    """Notices for one client; ``first_index`` numbers them so the client sees any gap."""

    first_index: int
    notices: list[Notice]


encoder = msgspec.msgpack.Encoder()
batch_decoder = msgspec.msgpack.Decoder(NoticeBatch)
answer_decoder = msgspec.msgpack.Decoder(Answer)
subscribe_decoder = msgspec.msgpack.Decoder(SubscribeRequest)
components_decoder = msgspec.msgpack.Decoder(ComponentsReply)
protocol_decoder = msgspec.msgpack.Decoder(int)
estop_decoder = msgspec.msgpack.Decoder(EstopReply)
lifecycle_request_decoder = msgspec.msgpack.Decoder(LifecycleRequest)
lifecycle_decoder = msgspec.msgpack.Decoder(LifecycleReply)
conf_request_decoder = msgspec.msgpack.Decoder(ConfRequest)
conf_decoder = msgspec.msgpack.Decoder(ConfReply)
