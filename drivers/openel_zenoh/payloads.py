"""Execute payloads as a SurfaceServer receives them: XML or the compact form, told by
their first characters, and decoded (the small compact ones once per distinct payload)."""

from __future__ import annotations

from openel_async.surface import compact, xml_psm
from openel_async.surface.messages import Device

DECODED_CACHE_SIZE = 256
"""Distinct compact execute payloads whose decoded Device is kept (then all are dropped)."""
DECODED_CACHE_MAX_BYTES = 256
"""Larger compact payloads are decoded every time."""


class DecodedPayloads:
    """Execute payloads decoded, the small compact ones once per distinct payload: a client
    sends the same bytes for each read of a component (RemoteActuator encodes its
    GetPosition once), and a decoded Device is immutable (frozen structs, lists as
    tuples), so one serves every copy. Shared by the loop and Zenoh's threads: a dict's
    get, set and clear are atomic under the GIL."""

    def __init__(
        self, size: int = DECODED_CACHE_SIZE, max_bytes: int = DECODED_CACHE_MAX_BYTES
    ) -> None:
        self.size = size
        self.max_bytes = max_bytes
        self._devices: dict[bytes, Device] = {}

    def decode(self, payload: bytes) -> tuple[Device, bool]:
        """The Device of ``payload`` and whether it was XML; BadParameterError if none."""
        devices = self._devices
        device = devices.get(payload)
        if device is not None:
            return device, False
        if is_xml(payload):
            return xml_psm.device_from_xml(payload), True
        device = compact.device_from_compact(payload)
        if len(payload) <= self.max_bytes:
            if len(devices) >= self.size:
                devices.clear()  # (all at once: no iteration another thread could upset)
            devices[payload] = device
        return device, False


_BOMS = (b"\xef\xbb\xbf", b"\xfe\xff", b"\xff\xfe", b"\x00\x00\xfe\xff")
"""UTF-8, UTF-16 BE, UTF-16 LE (and UTF-32 LE: FF FE 00 00), UTF-32 BE byte order marks."""
_WIDE = ("utf-16-le", "utf-16-be", "utf-32-le", "utf-32-be")


_MSGPACK_CONTAINERS = frozenset((*range(0x80, 0xA0), 0xDC, 0xDD, 0xDE, 0xDF))
"""First bytes of a msgpack array or map (fixmap, fixarray, array 16/32, map 16/32)."""


def is_xml(payload: bytes) -> bool:
    """Whether an execute payload is XML rather than the compact (msgpack) form: a byte order
    mark, or '<' as its first character after whitespace in UTF-8 or, without a mark, in
    UTF-16 or UTF-32 (the detection of XML 1.0 Appendix F; a compact Device starts with a
    msgpack array or map, never with these bytes). A payload that starts like a compact
    one is answered from its first byte: none of the byte order marks, whitespace or '<'
    in any of those encodings starts with a msgpack container's first byte."""
    if payload[:1] and payload[0] in _MSGPACK_CONTAINERS:
        return False
    if payload.startswith(_BOMS) or payload.lstrip(b" \t\r\n")[:1] == b"<":
        return True
    head = payload[:64]
    for encoding in _WIDE:
        width = 2 if "16" in encoding else 4
        try:
            text = head[: len(head) - len(head) % width].decode(encoding)
        except UnicodeDecodeError:
            continue
        if text.lstrip(" \t\r\n")[:1] == "<":
            return True
    return False
