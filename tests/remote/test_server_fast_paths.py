"""The server's per-request shortcuts: a compact payload told from XML by its first byte,
decoded Devices reused for identical payloads, and the gated loop's short waits timed to
the microsecond instead of epoll's millisecond."""

from __future__ import annotations

import selectors
from typing import Any

import pytest

from openel_async import BadParameterError
from openel_async.surface import CommandMessage, Device, compact, xml_psm
from openel_zenoh import gate
from openel_zenoh.gate import GatedSelector, LoopGate
from openel_zenoh.payloads import DecodedPayloads, is_xml

CONTAINER_FIRST_BYTES = [*range(0x80, 0xA0), 0xDC, 0xDD, 0xDE, 0xDF]


@pytest.mark.parametrize("first", CONTAINER_FIRST_BYTES)
def test_a_payload_starting_as_a_msgpack_container_is_never_xml(first: int) -> None:
    # what follows cannot make it XML: no byte order mark, whitespace or '<', in any
    # of the encodings XML detection knows, starts with these bytes
    for tail in (b"", b"<Device/>", b"\x00<\x00", b" \n<", b"\xfe\xff<"):
        assert not is_xml(bytes([first]) + tail)


@pytest.mark.parametrize(
    "payload",
    [b"<Device/>", b" \t<D/>", b"\xef\xbb\xbf<D/>", "<D/>".encode("utf-16-le"),
     "<D/>".encode("utf-16-be"), "<D/>".encode("utf-32-be")],
)  # fmt: skip
def test_xml_is_still_xml(payload: bytes) -> None:
    assert is_xml(payload)


def get_position() -> Device:
    return Device("Motor", (CommandMessage.call("GetPosition", "", logical_id=0),))


def test_identical_compact_payloads_are_decoded_once() -> None:
    payloads = DecodedPayloads(size=2)
    payload = compact.encode(get_position())
    first, xml = payloads.decode(payload)
    assert first == get_position() and not xml
    assert payloads.decode(bytes(payload))[0] is first  # an equal payload: the same Device
    other = compact.encode(Device("Motor", (CommandMessage.call("GetState", "", logical_id=0),)))
    payloads.decode(other)
    payloads.decode(compact.encode(Device("Motor", (CommandMessage.call("GetSpeed", ""),))))
    assert payloads.decode(payload)[0] is not first  # full: forgotten, decoded anew
    device, xml = payloads.decode(xml_psm.to_xml(get_position()))
    assert xml and device == get_position()
    with pytest.raises(BadParameterError):
        payloads.decode(b"\x93\xff")


class RecordingEpoll(selectors.EpollSelector):
    def __init__(self) -> None:
        super().__init__()
        self.timeouts: list[float | None] = []

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        self.timeouts.append(timeout)
        return super().select(timeout)


@pytest.mark.skipif(not hasattr(selectors, "EpollSelector"), reason="epoll: Linux")
def test_a_short_wait_is_not_rounded_up_to_a_millisecond(monkeypatch: pytest.MonkeyPatch) -> None:
    waits: list[float] = []

    def fake_select(r: Any, w: Any, x: Any, timeout: float) -> Any:
        waits.append(timeout)
        return [], [], []

    monkeypatch.setattr(gate.select, "select", fake_select)
    inner = RecordingEpoll()
    lock = LoopGate()
    selector = GatedSelector(lock, inner)
    try:
        selector.select(0.0002)  # below FINE_WAIT_BELOW: select() on the epoll fd
        assert waits == [0.0002]
        assert inner.timeouts == [0, 0]  # epoll only polled, before and after
        selector.select(0.05)  # longer: epoll's own wait
        assert inner.timeouts[-1] == 0.05 and waits == [0.0002]
        selector.select(0)
        assert inner.timeouts[-1] == 0 and waits == [0.0002]
    finally:
        selector.close()
