"""Payloads of the Zenoh transport other than HAL4RT messages (MessagePack, msgspec).

``execute`` carries a HAL4RT ``Device`` message, as XML (the standard PSM; a payload
starting with '<') or compact MessagePack; the reply uses the request's encoding. The
other queryables and the notice stream use the structures below.
"""

from __future__ import annotations

import msgspec

from openel_async.surface.messages import ResultList


class SubscribeRequest(msgspec.Struct, array_like=True):
    device_kind: str
    event_type: str


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
components_decoder = msgspec.msgpack.Decoder(list[ComponentInfo])
