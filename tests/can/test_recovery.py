"""Bus-off / adapter unplugged with components on the bus: faults, survival, re_init."""

from __future__ import annotations

import anyio
import pytest

from openel_async import (
    Actuator,
    ComponentState,
    DeviceFaultError,
    ErrorId,
    HALError,
    Request,
    Sensor,
)
from openel_async.testing import EventRecorder
from openel_can import CanBus, Cia402Drive, ODriveAxis, ODriveEncoder
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.faults import BusLink
from openel_can.sim.odrive import SimODrive

from .conftest import Peers, wait_until


@pytest.mark.parametrize("reopen", [True, False], ids=["reopen", "given-bus"])
async def test_bus_off_faults_every_component_and_re_init_recovers(
    channel: str, peers: Peers, recorder: EventRecorder, reopen: bool
) -> None:
    odrive = await peers.start(SimODrive(1, heartbeat_period=0.02))
    await peers.start(SimCia402Drive(2))
    link = BusLink(channel)
    given = None if reopen else link.open()
    options = {"poll_interval": 0.01, "reconnect_backoff": (0.01, 0.05)}
    bus = CanBus(bus_factory=link.open, **options) if given is None else CanBus(given, **options)  # type: ignore[arg-type]
    try:
        async with (
            bus,
            Actuator(ODriveAxis(bus, 1, heartbeat_period=0.02, engage_timeout=0.2)) as axis1,
            Actuator(Cia402Drive(bus, 2, heartbeat_ms=50)) as axis2,
            Sensor(ODriveEncoder(bus, 1)) as encoder,
        ):
            components = (axis1, axis2, encoder)
            for component in components:
                component.add_observer(recorder)
            motion = await axis1.set_value(1.0)
            link.fail("bus-off", unplugged=reopen)
            for component in components:
                record = await recorder.wait_for("error", source=component, timeout=1)
                assert record.id == ErrorId.BUS_ERROR
                assert component.state is ComponentState.ERROR
            with pytest.raises(DeviceFaultError):
                await motion
            with pytest.raises(HALError):
                await axis1.re_init()  # the bus is still down
            link.restore()
            with anyio.fail_after(2):
                await bus.wait_up(2)
                for component in components:
                    await component.re_init()
            assert all(c.state is ComponentState.ACTIVE for c in components)
            assert bus.stats.recoveries == 1
            with anyio.fail_after(2):
                await (await axis1.set_value(0.5))
                await (await axis2.set_value(0.5, Request.POSITION))
            assert (await encoder.get_value())[0] == pytest.approx(0.5, abs=1e-3)
            assert odrive.malformed == 0
            # One fault per component for the whole episode (heartbeat loss included).
            assert [r.id for r in recorder.errors] == [ErrorId.BUS_ERROR] * 3
    finally:
        if given is not None:
            given.shutdown()


async def test_reader_survives_a_storm_of_failures(channel: str) -> None:
    link = BusLink(channel)
    async with CanBus(
        bus_factory=link.open, poll_interval=0.01, reconnect_backoff=(0.005, 0.01)
    ) as bus:
        for _ in range(5):
            link.fail()
            await wait_until(lambda: not bus.is_up, 1)
            link.restore()
            await bus.wait_up(1)
        assert bus.stats.bus_errors == 5 and bus.stats.recoveries == 5
