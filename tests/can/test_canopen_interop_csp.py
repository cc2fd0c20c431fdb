"""Cyclic synchronous position against canopen-py, an independent CANopen implementation,
on python-can ``virtual`` and through python-can's ``slcan`` interface on a pty (our
simulated slcan adapter, :class:`~openel_can.sim.slcan.SlcanAdapter`):

(a) OUR master -- ``Cia402Drive(mode="csp", eds=...)`` with its configure/verify sequence,
    NMT, power state machine, CanSync on an EventTimer and a set-point per SYNC -- drives
    canopen's ``LocalNode`` loaded from the shipped EDS; the CiA 402 device behaviour
    (state machine, CSP latch at SYNC, statusword on change) is the application glue
    canopen-py leaves to its user, written here on canopen's callbacks.
(b) canopen's ``RemoteNode`` with its ``pdo`` and ``sync`` tooling masters OUR simulated
    drive (:class:`~openel_can.sim.cia402.SimCia402Drive`) in CSP: maps RPDO1/TPDO1/TPDO2,
    writes 0x60C2 and 0x6060 = 8, enables through its RPDO while its SYNC runs, then
    streams a target per SYNC and reads the position from the synchronous TPDO.

canopen's blocking calls run in a worker thread; every wait is bounded.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import canopen
import pytest
from canopen.pdo.base import PdoMap

from openel_async import Actuator, EventTimer, Request
from openel_can import CanBus, CanSync, Cia402CyclicDrive, Cia402Drive
from openel_can import canopen as co
from openel_can import cia402 as ds
from openel_can.od import SHIPPED_EDS
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.slcan import SlcanAdapter

from .conftest import Peers, canopen_network, in_thread, through_slcan, wait_until

T = TypeVar("T")
NODE = 6
PS = ds.PowerState
CSP = int(ds.ModeOfOperation.CYCLIC_SYNC_POSITION)
FOLLOWS = int(ds.StatusBit.SETPOINT_ACKNOWLEDGE)  # bit 12 in CSP: follows the command value


@pytest.fixture
def network(channel: str) -> Iterator[canopen.Network]:
    with canopen_network(interface="virtual", channel=channel, receive_own_messages=False) as net:
        yield net


# -- (a) our master, canopen's LocalNode as a CSP drive ---------------------------------------
class _CspDevice:
    """The application of a CiA 402 device on canopen's LocalNode (all callbacks run in
    canopen's notifier thread): the power state machine on the controlword (SDO or RPDO),
    0x6061 following 0x6060, the statusword computed on read and sent on change by the
    event-driven TPDOs, and in CSP the target latched at each SYNC, answered by the
    synchronous TPDOs."""

    def __init__(self, node: canopen.LocalNode, network: canopen.Network) -> None:
        self.node = node
        self.network = network
        self.state = PS.SWITCH_ON_DISABLED
        self.controlword = 0
        self.mode = 1
        self.position = 0
        self.syncs = 0
        self.lock = threading.Lock()
        self._started = False
        node.add_read_callback(self._on_read)
        node.add_write_callback(self._on_write)
        network.subscribe(0, self._on_nmt)  # after the node's own NMT handler

    def statusword(self) -> int:
        enabled = self.state is PS.OPERATION_ENABLED
        halted = bool(self.controlword & ds.ControlBit.HALT)
        word = ds.Statusword.build(self.state, target_reached=enabled and halted).raw
        if enabled and self.mode == CSP and not halted:
            word |= FOLLOWS
        return word

    def _on_read(self, index: int, subindex: int, od: Any) -> int | None:
        return {0x6041: self.statusword(), 0x6061: self.mode, 0x6064: self.position}.get(index)

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        if index == 0x6060:
            self.mode = int.from_bytes(data, "little", signed=True)
            self._status_changed()
        elif index == 0x6040:
            word = int.from_bytes(data, "little")
            before = self.statusword()
            self.state = ds.apply_controlword(
                self.state, word, previous_controlword=self.controlword
            )
            self.controlword = word
            if self.statusword() != before:
                self._status_changed()

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self.node.nmt.state != "OPERATIONAL" or self._started:
            return
        self._started = True  # the PDO configuration the master wrote, from the node's OD
        self.node.tpdo.read()
        self.node.rpdo.read()
        for rpdo in self.node.rpdo.map.values():
            if rpdo.enabled:
                rpdo.add_callback(self._apply)
        self.network.subscribe(co.SYNC_COB_ID, self._on_sync)
        self._status_changed()  # event-driven TPDOs go out at once on NMT start

    def _apply(self, rpdo: PdoMap) -> None:
        for var in rpdo:
            self.node.set_data(var.index, var.subindex, var.get_data())

    def _transmit(self, synchronous: bool) -> None:
        for tpdo in self.node.tpdo.map.values():
            trans = tpdo.trans_type
            if not tpdo.enabled or trans is None or (1 <= trans <= 240) != synchronous:
                continue
            if not synchronous and all(var.index != 0x6041 for var in tpdo):
                continue
            for var in tpdo:
                var.set_data(self.node.get_data(var.index, var.subindex))
            tpdo.transmit()

    def _status_changed(self) -> None:
        if self._started:
            self._transmit(synchronous=False)

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self.lock:
            self.syncs += 1
        if self.state is PS.OPERATION_ENABLED and self.mode == CSP:
            target = self.node.get_data(0x607A, 0)
            self.position = int.from_bytes(target, "little", signed=True)  # latched
        self._transmit(synchronous=True)


async def test_our_master_drives_a_canopen_local_node_in_csp(
    network: canopen.Network, host_bus: CanBus
) -> None:
    await _our_master_csp(network, host_bus)


async def test_our_master_through_slcan_drives_a_canopen_local_node_in_csp() -> None:
    await through_slcan(_our_master_csp)


async def _our_master_csp(network: canopen.Network, host_bus: CanBus) -> None:
    local = canopen.LocalNode(NODE, str(SHIPPED_EDS))
    network.add_node(local)
    device = _CspDevice(local, network)
    local.nmt.state = "PRE-OPERATIONAL"
    drive = Cia402Drive(host_bus, NODE, mode="csp", eds=SHIPPED_EDS, heartbeat_ms=100)
    assert isinstance(drive, Cia402CyclicDrive)
    async with Actuator(drive) as axis, EventTimer(2.0, name="cycle") as timer:
        # configured from the EDS's default CSP maps, verified, started, enabled
        assert local.sdo[0x1600][2].raw == 0x607A_0020 and local.sdo[0x1400][2].raw == 1
        assert local.sdo[0x1801][2].raw == 0xFF and local.sdo[0x1A01][1].raw == 0x6041_0010
        assert local.nmt.state == "OPERATIONAL"
        assert device.state is PS.OPERATION_ENABLED and device.mode == CSP
        sync = CanSync.of(host_bus)
        await sync.start(timer)
        try:
            assert (local.sdo[0x60C2][1].raw, local.sdo[0x60C2][2].raw) == (2, -3)
            timer.start_timer()
            for target in (0.5, -0.25):
                await axis.set_value(target)
                counts = round(target * 10_000 / math.tau)
                await wait_until(lambda c=counts: device.position == c)  # type: ignore[misc]
                await wait_until(lambda: drive.feedback_cycle >= sync.cycle - 1)
                await wait_until(lambda c=counts: drive._position == c)  # type: ignore[misc]
                actual = await axis.get_value(Request.POSITION_ACTUAL)
                assert actual == pytest.approx(target, abs=1e-3)
            assert device.syncs >= 2 and sync.stats.rpdos >= 2
        finally:
            sync.stop()
    # closing left CSP (halt, profile position) and shut the drive down
    assert device.mode == 1 and device.state is PS.READY_TO_SWITCH_ON


# -- (b) canopen's RemoteNode masters our simulated drive in CSP -------------------------------
def _wait(predicate: Callable[[], bool], what: str, timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f"canopen master: {what}")
        time.sleep(0.002)


def _master_csp(network: canopen.Network, remote: canopen.RemoteNode) -> dict[str, Any]:
    """What a canopen-py user writes for CSP: blocking, in a thread."""
    out: dict[str, Any] = {}
    remote.nmt.state = "PRE-OPERATIONAL"
    remote.tpdo.read()
    remote.rpdo.read()
    rpdo = remote.rpdo[1]
    rpdo.clear()
    rpdo.add_variable("Controlword")
    rpdo.add_variable("Target position")
    rpdo.trans_type = 1  # applied at the next SYNC
    rpdo.enabled = True
    tpdo = remote.tpdo[1]
    tpdo.clear()
    tpdo.add_variable("Statusword")
    tpdo.add_variable("Position actual value")
    tpdo.trans_type = 1  # every SYNC
    tpdo.enabled = True
    for n in (2, 3, 4):
        remote.tpdo[n].enabled = False
    for n in (2, 3, 4):
        remote.rpdo[n].enabled = False
    remote.rpdo.save()
    remote.tpdo.save()
    remote.sdo["Interpolation time period"]["Interpolation time period value"].raw = 5
    remote.sdo["Interpolation time period"]["Interpolation time index"].raw = -3
    remote.sdo["Target position"].raw = 0
    remote.sdo["Modes of operation"].raw = CSP
    out["display"] = remote.sdo["Modes of operation display"].raw
    remote.nmt.state = "OPERATIONAL"
    network.sync.start(0.005)
    tpdo.wait_for_reception(timeout=1)

    def state() -> PS:
        return ds.state_from_statusword(int(tpdo["Statusword"].raw))

    def command(word: int, target: int = 0) -> None:
        rpdo["Controlword"].raw = word
        rpdo["Target position"].raw = target
        rpdo.transmit()

    for word, wanted in (
        (0x06, PS.READY_TO_SWITCH_ON),
        (0x07, PS.SWITCHED_ON),
        (0x0F, PS.OPERATION_ENABLED),
    ):
        command(word)
        _wait(lambda w=wanted: state() is w, f"{wanted.name} after {word:#x}")  # type: ignore[misc]
    _wait(lambda: bool(int(tpdo["Statusword"].raw) & FOLLOWS), "drive follows (bit 12)")
    # A set-point every SYNC: a ramp to 2000 increments, 50 per cycle.
    for k in range(1, 41):
        tpdo.wait_for_reception(timeout=1)
        command(0x0F, 50 * k)
    _wait(lambda: tpdo["Position actual value"].raw == 2000, "position 2000", timeout=3)
    out["position"] = tpdo["Position actual value"].raw
    out["period"] = tpdo.period
    network.sync.stop()
    return out


async def test_canopen_master_runs_our_simulated_drive_in_csp(
    peers: Peers, network: canopen.Network
) -> None:
    sim = await peers.start(SimCia402Drive(NODE, heartbeat_ms=0))
    remote = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
    network.add_node(remote)
    out = await in_thread(lambda: _master_csp(network, remote))
    _check_csp(out, sim)


async def test_canopen_master_through_slcan_runs_our_simulated_drive_in_csp() -> None:
    sim = SimCia402Drive(NODE, heartbeat_ms=0)
    with (
        SlcanAdapter(peers=[sim]) as adapter,
        canopen_network(
            interface="slcan", channel=adapter.port, bitrate=1_000_000, sleep_after_open=0
        ) as net,
    ):
        remote = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
        net.add_node(remote)
        out = await in_thread(lambda: _master_csp(net, remote), limit=20)
    _check_csp(out, sim)
    assert adapter.stats.errors == 0


def _check_csp(out: dict[str, Any], sim: SimCia402Drive) -> None:
    assert out["display"] == CSP and out["position"] == 2000
    assert sim.mode == CSP and sim.power_state is PS.OPERATION_ENABLED
    assert sim.interpolation_period_ns() == 5_000_000
    assert round(sim.position) == 2000 and sim.syncs > 40
    assert out["period"] is not None and out["period"] < 0.05  # TPDO1 on every SYNC
