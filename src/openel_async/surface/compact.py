"""The compact encoding of HAL4RT messages: MessagePack (msgspec) of the same model.

Each structure is an array of its fields in table order, a parameter ``[data_type_id,
name, value]`` with bytes as MessagePack bin and lists as arrays. Decoding runs the same
checks as construction, so a decoded message is as valid as one read from XML. XML stays
the standard PSM; this encoding is for speed (``openel-async serve`` accepts both).
"""

from __future__ import annotations

from typing import Any, TypeVar

import msgspec

from ..errors import BadParameterError
from .messages import Device, Message

MAX_COMPACT_BYTES = 1 << 20
"""Largest compact message accepted (1 MiB)."""

T = TypeVar("T")
_encoder = msgspec.msgpack.Encoder()
_decoders: dict[Any, msgspec.msgpack.Decoder[Any]] = {}


def encode(message: Message | Any) -> bytes:
    """MessagePack bytes of a message (or of any msgspec-encodable value)."""
    return _encoder.encode(message)


def decode(data: bytes, kind: type[T], *, max_bytes: int = MAX_COMPACT_BYTES) -> T:
    """A ``kind`` decoded from MessagePack; BAD_PARAMETER when it is not one."""
    if len(data) > max_bytes:
        raise BadParameterError("message", f"<{len(data)} bytes>", f"at most {max_bytes} bytes")
    decoder = _decoders.get(kind)
    if decoder is None:
        decoder = _decoders[kind] = msgspec.msgpack.Decoder(kind)
    try:
        return decoder.decode(data)  # type: ignore[no-any-return]
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise BadParameterError(
            "message",
            f"<{len(data)} bytes>",
            f"a compact {getattr(kind, '__name__', kind)} ({exc})",
        ) from None


def device_from_compact(data: bytes, *, max_bytes: int = MAX_COMPACT_BYTES) -> Device:
    return decode(data, Device, max_bytes=max_bytes)
