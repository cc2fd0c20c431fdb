"""The ``serial`` bus kind of rig files (:mod:`openel_serial.rigbus`): strict options, what
``rig check`` refuses, ``rig show``'s line, the port it opens, and ``--sim``: a pty with
simulated servos at the rig's ids, models and baud rate (or a simulated GPS receiver) on a
thread of their own, driven through the real serial stack. Safety through the rig path: the
e-stop, the exit actions and ``kill -9`` of an app streaming goals (every servo stops by
itself within its Bus Watchdog timeout)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import anyio.abc
import msgspec
import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    ErrorId,
    EventId,
    HALError,
    MonotonicClock,
    Request,
)
from openel_async.gps import GPSSensor
from openel_async.rig import FaultInjection, SimulatedDevice, load_rig, open_rig, resolve_rig
from openel_async.safety import ExitAction
from openel_async.testing import EventRecorder
from openel_serial import (
    DRIVER,
    DynamixelPort,
    DynamixelServo,
    DynamixelTimeoutError,
    NmeaGps,
    SerialBusKind,
    SerialBusOptions,
)
from openel_serial import dynamixel as dx
from openel_serial.peers import SimGps, SimServo

from .conftest import WAIT_S

pytestmark = pytest.mark.timeout(60)

X = dx.XSeries
KIND = SerialBusKind()
NS = 1_000_000_000
APP = Path(__file__).with_name("rig_app.py")


def options(**fields: Any) -> SerialBusOptions:
    fields.setdefault("device", "/dev/ttyUSB0")
    fields.setdefault("baudrate", 1_000_000)
    fields.setdefault("protocol", "dynamixel")
    return msgspec.convert(fields, SerialBusOptions)


def servo(name: str, dxl_id: object, device: str = "dynamixel_xm430_w350") -> SimulatedDevice:
    return SimulatedDevice(name, "serial", device, {"dxl_id": dxl_id})


def gps(name: str = "GPS") -> SimulatedDevice:
    return SimulatedDevice(name, "serial", "nmea_gps", {})


SERVOS = (servo("J1", 1), servo("J2", 2, "dynamixel_xl430_w250"))


async def wait_until(predicate: Callable[[], bool], timeout: float = WAIT_S) -> None:  # noqa: ASYNC109
    """Poll a simulated peer's state (served on another thread: no event to await), bounded."""
    with anyio.fail_after(timeout):
        while not predicate():  # noqa: ASYNC110 - the condition has no event to wait on
            await anyio.sleep(0.002)


def sim_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("sim-peer ")]


# -- options ----------------------------------------------------------------------------------


def test_the_driver_registers_the_kind() -> None:
    assert isinstance(DRIVER.buses["serial"], SerialBusKind)
    assert SerialBusKind.options_type is SerialBusOptions


def test_options_are_strict() -> None:
    given = options()
    assert (given.device, given.baudrate, given.protocol) == (
        "/dev/ttyUSB0",
        1_000_000,
        "dynamixel",
    )
    assert (given.poll_period, given.return_delay, given.timeout_margin, given.retries) == (
        None, None, None, None,
    )  # fmt: skip
    with pytest.raises(msgspec.ValidationError, match="unknown field `baudrat`"):
        options(baudrat=9600)
    with pytest.raises(msgspec.ValidationError, match="Object missing required field `protocol`"):
        msgspec.convert({"device": "/dev/ttyUSB0", "baudrate": 9600}, SerialBusOptions)
    bad: list[dict[str, Any]] = [
        {"protocol": "modbus"},
        {"device": ""},
        {"baudrate": 0},
        {"baudrate": "1000000"},
        {"poll_period": -0.01},
        {"return_delay": 0.001},  # Return Delay Time (9) goes up to 254 x 2 us
        {"timeout_margin": 0},
        {"retries": -1},
        {"retries": 1.5},
    ]
    for fields in bad:
        with pytest.raises(msgspec.ValidationError):
            options(**fields)


def write_rig(tmp_path: Path, bus: str, components: Sequence[str] = (), extra: str = "") -> Path:
    path = tmp_path / "rig.yaml"
    entries = components or [
        "  - {name: J1, driver: serial, device: dynamixel_xm430_w350, bus: servos,"
        " params: {dxl_id: 1}}"
    ]
    text = "buses:\n  servos: {type: serial, " + bus + "}\ncomponents:\n"
    path.write_text(text + "\n".join(entries) + "\n" + extra)
    return path


DXL_BUS = "protocol: dynamixel, device: /dev/ttyUSB0, baudrate: 1000000"


def test_a_rig_file_refuses_a_bad_option_at_its_position(tmp_path: Path) -> None:
    resolve_rig(load_rig(write_rig(tmp_path, DXL_BUS + ", poll_period: 0.005, retries: 3")))
    with pytest.raises(
        BadParameterError,
        match=r"rig.yaml:2:\d+: unknown key 'baudrat' in buses.servos .did you mean 'baudrate'",
    ):
        resolve_rig(load_rig(write_rig(tmp_path, DXL_BUS + ", baudrat: 5")))
    with pytest.raises(BadParameterError, match=r"rig.yaml:2:\d+: buses.servos.return_delay"):
        resolve_rig(load_rig(write_rig(tmp_path, DXL_BUS + ", return_delay: 0.01")))
    with pytest.raises(BadParameterError, match="a Dynamixel X baud rate"):
        resolve_rig(load_rig(write_rig(tmp_path, DXL_BUS.replace("1000000", "1234"))))


# -- rig check ---------------------------------------------------------------------------------


def test_check_accepts_servos_and_a_receiver() -> None:
    KIND.check(options(), SERVOS)
    KIND.check(options(), [servo("J0", 0), servo("J252", 252, "dynamixel")])
    for rate in dx.BAUD_RATES:
        KIND.check(options(baudrate=rate), SERVOS)
    KIND.check(options(protocol="nmea", baudrate=9600), [gps()])
    KIND.check(options(protocol="nmea", baudrate=115_200), [])


@pytest.mark.parametrize(
    ("given", "devices", "parameter", "message"),
    [
        ({"baudrate": 1_234}, SERVOS, "baudrate", "a Dynamixel X baud rate: 9600, 57600"),
        ({"baudrate": 250_000}, SERVOS, "baudrate", "4500000"),
        ({"protocol": "nmea", "baudrate": 1_000_000}, [gps()], "baudrate", "receiver's baud"),
        ({}, [servo("J1", 1), servo("J2", 1)], "J2.params.dxl_id", r"own \(J1 has it\)"),
        ({}, [servo("J1", 253)], "J1.params.dxl_id", r"a servo id in 0\.\.252"),
        ({}, [servo("J1", -1)], "J1.params.dxl_id", r"0\.\.252"),
        ({}, [servo("J1", True)], "J1.params.dxl_id", r"0\.\.252"),
        ({}, [servo("J1", "1")], "J1.params.dxl_id", r"0\.\.252"),
        ({}, [SimulatedDevice("J1", "serial", "dynamixel", {})], "J1.params.dxl_id", "0..252"),
        ({}, [gps()], "GPS.device", "a dynamixel device"),
        ({"protocol": "nmea", "baudrate": 9600}, [servo("J1", 1)], "J1.device", "an? nmea"),
        ({"protocol": "nmea", "baudrate": 9600}, [gps("A"), gps("B")], "B.bus", "one GPS"),
        (
            {"protocol": "nmea", "baudrate": 9600, "poll_period": 0.01},
            [gps()],
            "poll_period",
            "only",
        ),
        ({"protocol": "nmea", "baudrate": 9600, "retries": 1}, [gps()], "retries", "dynamixel"),
        ({"poll_period": float("inf")}, SERVOS, "poll_period", "finite"),
    ],
)
def test_check_refuses(
    given: dict[str, Any], devices: list[SimulatedDevice], parameter: str, message: str
) -> None:
    with pytest.raises(BadParameterError, match=message) as caught:
        KIND.check(options(**given), devices)
    assert caught.value.parameter == parameter


def test_rig_check_refuses_a_servo_on_an_nmea_port(tmp_path: Path) -> None:
    path = write_rig(tmp_path, "protocol: nmea, device: /dev/ttyACM0, baudrate: 9600")
    # The entry's own arguments are checked first (rig check): an NMEA port gives no 'port'.
    # (The kind's own refusal, a servo on an NMEA port, is test_check_refuses's.)
    with pytest.raises(BadParameterError, match=r"rig.yaml:4:\d+: J1.params.*with port"):
        resolve_rig(load_rig(path))


# -- rig show, open ----------------------------------------------------------------------------


def test_describe() -> None:
    assert KIND.describe(options()) == "serial /dev/ttyUSB0 at 1000000 baud, Dynamixel 2.0"
    nmea = options(protocol="nmea", device="/dev/ttyACM0", baudrate=9600)
    assert KIND.describe(nmea) == "serial /dev/ttyACM0 at 9600 baud, NMEA 0183"


def test_open_gives_a_port_with_the_tuning_and_the_devices_their_arguments() -> None:
    port = KIND.open("servos", options(poll_period=0.005, return_delay=0.0, retries=4))
    assert isinstance(port, DynamixelPort)
    assert (port.url, port.baudrate, port.poll_period, port.return_delay, port.retries) == (
        "/dev/ttyUSB0", 1_000_000, 0.005, 0.0, 4,
    )  # fmt: skip
    assert port.timeout_margin == 0.02  # the port's default
    assert KIND.device_arguments(port, options(), SERVOS[0]) == {"port": port}
    nmea = options(protocol="nmea", device="/dev/ttyACM0", baudrate=4800)
    assert KIND.device_arguments(object(), nmea, gps()) == {"url": "/dev/ttyACM0", "baudrate": 4800}


async def test_an_nmea_port_opens_nothing() -> None:
    nmea = options(protocol="nmea", device="/dev/does-not-exist", baudrate=9600)
    async with KIND.open("gps", nmea) as opened:
        assert opened is nmea


# -- --sim ---------------------------------------------------------------------------------------


async def test_simulated_servos_have_the_rigs_ids_models_baud_rate_and_return_delay() -> None:
    given = options(baudrate=57_600, return_delay=100e-6)
    async with KIND.simulate("servos", given, SERVOS) as sim:
        assert len(sim_threads()) == 1
        assert isinstance(sim.options, SerialBusOptions)
        assert sim.options.device != given.device and await anyio.Path(sim.options.device).exists()
        assert msgspec.structs.replace(sim.options, device=given.device) == given
        assert sim.description == (
            f"pty {sim.options.device} at 57600 baud with simulated Dynamixel servos 1, 2"
        )
        j1, j2 = sim.peers["J1"], sim.peers["J2"]
        assert isinstance(j1, SimServo) and isinstance(j2, SimServo)
        assert (j1.id, j1.model_number, j2.id, j2.model_number) == (1, 1020, 2, 1060)
        for peer in (j1, j2):
            assert isinstance(peer, FaultInjection)
            assert peer.baudrate == 57_600 and peer.get_raw(X.BAUD_RATE) == 1
            assert peer.get_raw(X.RETURN_DELAY_TIME) == 50  # 100 us in 2 us units
    assert sim_threads() == []  # the peer's thread stopped with it


async def test_servos_do_not_hear_a_port_at_another_baud_rate() -> None:
    given = options(baudrate=57_600)
    async with KIND.simulate("servos", given, SERVOS[:1]) as sim:
        url = sim.options.device
        async with DynamixelPort(url, baudrate=1_000_000, retries=0, return_delay=0.0) as port:
            with anyio.fail_after(WAIT_S), pytest.raises(DynamixelTimeoutError):
                await port.ping(1)
        async with DynamixelPort(url, baudrate=57_600, return_delay=0.0) as port:
            with anyio.fail_after(WAIT_S):
                info = await port.ping(1)
        assert info.model_number == 1020


async def test_a_simulated_bus_drives_servos_through_actuators() -> None:
    """The rig's path by hand: simulate, open the options it gives, build each servo with
    the kind's arguments; a position move completes on the pty."""
    recorder = EventRecorder(MonotonicClock())
    given = options(poll_period=0.005, return_delay=0.0)
    async with (
        KIND.simulate("servos", given, SERVOS) as sim,
        KIND.open("servos", sim.options) as port,
    ):
        assert isinstance(port, DynamixelPort) and port.baudrate == 1_000_000
        devices = {
            d.name: DRIVER.devices[d.device](**d.params, **KIND.device_arguments(port, given, d))
            for d in SERVOS
        }
        assert type(devices["J2"]).__name__ == "DynamixelXL430W250"
        async with Actuator(devices["J1"]) as j1, Actuator(devices["J2"]) as j2:
            for actuator in (j1, j2):
                actuator.add_observer(recorder)
            with anyio.fail_after(WAIT_S):
                motions = [await j1.set_value(0.4), await j2.set_value(-0.3)]
                for motion in motions:
                    await motion
            for actuator in (j1, j2):
                await recorder.wait_for("event", EventId.COMPLETED, source=actuator, timeout=1)
            assert await j1.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.4, abs=0.01)
            assert await j2.get_value(Request.POSITION_ACTUAL) == pytest.approx(-0.3, abs=0.01)
            peer = sim.peers["J1"]
            assert isinstance(peer, SimServo)
            assert peer.state()[0] == pytest.approx(dx.rad_to_ticks(0.4), abs=4)
            assert recorder.errors == []


async def test_an_injected_fault_overheats_the_servo_and_faults_its_component() -> None:
    recorder = EventRecorder(MonotonicClock())
    given = options(poll_period=0.005, return_delay=0.0)
    async with (
        KIND.simulate("servos", given, SERVOS[:1]) as sim,
        KIND.open("servos", sim.options) as port,
    ):
        assert isinstance(port, DynamixelPort)
        async with Actuator(DynamixelServo(port, 1, reboot_on_alert=False)) as j1:
            j1.add_observer(recorder)
            peer = sim.peers["J1"]
            assert isinstance(peer, FaultInjection) and isinstance(peer, SimServo)
            peer.inject_fault("injected over-temperature")  # from this thread: applied there
            await recorder.wait_for("error", ErrorId.DEVICE_ERROR, source=j1, timeout=WAIT_S)
            assert j1.state is ComponentState.ERROR
            assert "OVERHEATING" in str(j1.last_fault)
            assert peer.fault_reason == "injected over-temperature"
            assert peer.hardware_error == dx.HardwareError.OVERHEATING
            assert not peer.torque_enabled
            assert peer.get_raw(X.PRESENT_TEMPERATURE) > peer.get_raw(X.TEMPERATURE_LIMIT)


async def test_a_simulated_receiver_gives_a_fix_through_a_sensor() -> None:
    given = options(protocol="nmea", device="/dev/ttyACM0", baudrate=9600)
    async with KIND.simulate("gps", given, [gps()]) as sim, KIND.open("gps", sim.options) as bus:
        assert sim.description.endswith("at 9600 baud with a simulated NMEA receiver")
        peer = sim.peers["GPS"]
        assert isinstance(peer, SimGps) and isinstance(peer, FaultInjection)
        device = NmeaGps(**KIND.device_arguments(bus, sim.options, gps()))
        assert device.url == sim.options.device
        async with GPSSensor(device) as sensor:
            with anyio.fail_after(WAIT_S):
                while not device.fix.valid:
                    await device.next_fix()
            assert await sensor.get_latitude() == pytest.approx(peer.track.latitude, abs=1e-3)
            assert await sensor.get_longitude() == pytest.approx(peer.track.longitude, abs=1e-3)
            assert not await sensor.is_stale()
            peer.inject_fault("antenna cut")
            with anyio.fail_after(WAIT_S):
                while device.fix.valid:
                    await device.next_fix()
            assert await sensor.is_stale()
            assert sensor.state is ComponentState.ACTIVE  # no fix is not a fault
    assert sim_threads() == []


# -- safety through a rig with --sim --------------------------------------------------------------

RIG_SERVOS = [
    "  - {name: J1, driver: serial, device: dynamixel_xm430_w350, bus: servos,"
    " params: {dxl_id: 1}}",
    "  - {name: J2, driver: serial, device: dynamixel_xl430_w250, bus: servos,"
    " params: {dxl_id: 2}}",
]


def servo_rig(tmp_path: Path, on_exit: str = "hold", device: str = "/dev/ttyUSB0") -> Path:
    bus = f"protocol: dynamixel, device: {device}, baudrate: 1000000, poll_period: 0.005"
    safety = f"safety: {{watchdog_timeout: 0.1, on_exit: {on_exit}}}\n"
    return write_rig(tmp_path, bus, RIG_SERVOS, safety)


def peers_of(peers: dict[str, object]) -> list[SimServo]:
    out = [peers["J1"], peers["J2"]]
    assert all(isinstance(p, SimServo) for p in out)
    return out  # type: ignore[return-value]


async def test_the_rig_estop_turns_every_servo_torque_off_until_released(tmp_path: Path) -> None:
    recorder = EventRecorder(MonotonicClock())
    async with open_rig(load_rig(servo_rig(tmp_path)), MonotonicClock(), sim=True) as rig:
        servos = peers_of(rig.peers)
        assert [s.get_raw(X.BUS_WATCHDOG) for s in servos] == [5, 5]  # armed: 0.1 s
        for actuator in rig.actuators:
            actuator.add_observer(recorder)
            await actuator.set_value(2.0, Request.VELOCITY)
        await rig.estop()
        for actuator in rig.actuators:
            await recorder.wait_for("error", ErrorId.ESTOP, source=actuator, timeout=WAIT_S)
            assert actuator.state is ComponentState.ERROR
        # One SYNC WRITE (no reply): the servos' thread applies it when it reads it.
        await wait_until(lambda: not any(s.torque_enabled for s in servos))
        with pytest.raises(HALError, match="e-stop is not released"):
            await rig.actuator("J1").re_init()
        rig.release_estop()
        for actuator in rig.actuators:
            await actuator.re_init()
            assert actuator.state is ComponentState.ACTIVE
        assert [s.torque_enabled for s in servos] == [True, True]  # (writes acknowledged)
        with anyio.fail_after(WAIT_S):
            await (await rig.actuator("J1").set_value(0.2))


@pytest.mark.parametrize("on_exit", ["hold", "torque_off"])
async def test_the_rig_leaves_every_servo_as_on_exit_says(tmp_path: Path, on_exit: str) -> None:
    async with open_rig(load_rig(servo_rig(tmp_path, on_exit)), MonotonicClock(), sim=True) as rig:
        servos = peers_of(rig.peers)
        for actuator in rig.actuators:
            await actuator.set_value(2.0, Request.VELOCITY)
        # Turning, well away from where they started.
        await wait_until(lambda: all(abs(s.state()[0] - dx.CENTER_TICK) > 100 for s in servos))
    assert [(r.component, r.action, r.ok) for r in rig.exit_report] == [
        ("J1", ExitAction(on_exit), True),
        ("J2", ExitAction(on_exit), True),
    ]
    for peer in servos:  # (their thread stopped with the rig)
        # The state asked for outlives the host: the Bus Watchdog is disarmed.
        assert peer.get_raw(X.BUS_WATCHDOG) == 0 and not peer.watchdog_tripped
        if on_exit == "torque_off":
            assert not peer.torque_enabled
        else:
            assert peer.torque_enabled and peer.mode == dx.OperatingMode.POSITION
            goal = peer.get_raw(X.GOAL_POSITION)
            assert abs(goal - dx.CENTER_TICK) > 100  # where it was when the rig closed
            assert peer.state() == (goal, 0.0)  # holding there


async def test_a_stalled_loop_lets_every_servo_stop_by_itself(tmp_path: Path) -> None:
    """Block the event loop for 3x the rig's watchdog timeout: the servos (on their own
    thread and clock) stop by themselves during the stall, one timeout after the last poll;
    each component reports ErrorId.WATCHDOG when the loop resumes; re_init recovers."""
    recorder = EventRecorder(MonotonicClock())
    timeout_s = 0.1
    async with open_rig(load_rig(servo_rig(tmp_path)), MonotonicClock(), sim=True) as rig:
        servos = peers_of(rig.peers)
        for actuator in rig.actuators:
            actuator.add_observer(recorder)
            await actuator.set_value(2.0, Request.VELOCITY)  # would turn for ever
        stall_start = time.monotonic_ns()
        time.sleep(3 * timeout_s)  # noqa: ASYNC251 - the stall under test: nothing feeds
        stall_end = time.monotonic_ns()
        for actuator in rig.actuators:
            await recorder.wait_for("error", ErrorId.WATCHDOG, source=actuator, timeout=WAIT_S)
            assert actuator.state is ComponentState.ERROR
            assert "Bus Watchdog expired" in str(actuator.last_fault)
        for peer in servos:
            assert peer.watchdog_tripped_ns is not None
            # (+20 ms: the last poll before the stall may reach the servos' thread late)
            assert stall_start < peer.watchdog_tripped_ns <= stall_start + round(0.12 * NS)
            assert peer.watchdog_tripped_ns < stall_end and peer.state()[1] == 0.0
        for actuator in rig.actuators:
            await actuator.re_init()
        assert [s.get_raw(X.BUS_WATCHDOG) for s in servos] == [5, 5]  # cleared, armed again
        with anyio.fail_after(WAIT_S):
            await (await rig.actuator("J2").set_value(-0.2))
        assert recorder.count("error", ErrorId.WATCHDOG) == 2


@asynccontextmanager
async def streaming_app(tmp_path: Path) -> AsyncIterator[tuple[anyio.abc.Process, list[SimServo]]]:
    """Simulated servos served here (on a thread of their own) and the app streaming goals
    to them: a child process run from a rig file that names their pty (no ``--sim``), whose
    safety arms their Bus Watchdogs (100 ms) and leaves them holding at exit."""
    devices = [servo("J1", 1), servo("J2", 2, "dynamixel_xl430_w250")]
    async with KIND.simulate("servos", options(), devices) as sim:
        servos = peers_of(dict(sim.peers))
        rig = servo_rig(tmp_path, device=sim.options.device)
        async with await anyio.open_process(
            [sys.executable, "-m", "openel_async.cli", "run", str(APP), "--rig", str(rig)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            env=dict(os.environ, NO_COLOR="1"),
        ) as app:
            assert app.stdout is not None
            output = b""
            with anyio.fail_after(30):  # the child's start: imports, the rig's init
                while b"ready\n" not in output:
                    output += await app.stdout.receive()
            assert [s.get_raw(X.BUS_WATCHDOG) for s in servos] == [5, 5]  # armed by the rig
            goals = [s.get_raw(X.GOAL_POSITION) for s in servos]
            # The stream goes on: the goals change.
            await wait_until(lambda: [s.get_raw(X.GOAL_POSITION) for s in servos] != goals)
            try:
                yield app, servos
            finally:
                with contextlib.suppress(ProcessLookupError):  # ended already
                    app.kill()


async def rest_of(app: anyio.abc.Process) -> str:
    """What the app prints until it ends (bounded)."""
    assert app.stdout is not None
    output = b""
    with anyio.fail_after(20):
        with contextlib.suppress(anyio.EndOfStream):
            while True:
                output += await app.stdout.receive()
    return output.decode()


async def test_kill_9_of_an_app_streaming_goals_stops_every_servo_within_the_timeout(
    tmp_path: Path,
) -> None:
    """kill -9 of the app: every servo stops by itself within the timeout, with nobody left
    to tell it."""
    timeout_s = 0.1
    async with streaming_app(tmp_path) as (app, servos):
        killed_ns = time.monotonic_ns()
        app.send_signal(signal.SIGKILL)
        with anyio.fail_after(WAIT_S):
            assert await app.wait() == -signal.SIGKILL
        # The servos' own clock decides; no instruction reaches them any more.
        deadline_ns = killed_ns + round((timeout_s + 0.02) * NS)
        await wait_until(lambda: all(s.watchdog_tripped for s in servos))
        for s in servos:
            # Within the timeout of the kill (+20 ms: a packet in flight when it was killed).
            assert s.watchdog_tripped_ns is not None and s.watchdog_tripped_ns <= deadline_ns
            position, velocity = s.state()
            assert velocity == 0.0 and s.torque_enabled  # stopped, holding
            await anyio.sleep(0.03)
            assert s.state() == (position, 0.0)


async def test_sigterm_of_an_app_streaming_goals_leaves_every_servo_holding(
    tmp_path: Path,
) -> None:
    """SIGTERM: the run leaves every servo as ``safety.on_exit`` says (hold) and disarms its
    Bus Watchdog, so that the hold outlives the app."""
    async with streaming_app(tmp_path) as (app, servos):
        app.send_signal(signal.SIGTERM)
        out = await rest_of(app)
        with anyio.fail_after(WAIT_S):
            assert await app.wait() == 143, out
        assert "on exit            hold: J1 done, J2 done" in out
        await anyio.sleep(0.3)  # 3x the timeout with nobody on the bus
        for s in servos:
            assert s.get_raw(X.BUS_WATCHDOG) == 0 and not s.watchdog_tripped
            assert s.torque_enabled and s.state()[1] == 0.0
            assert s.state()[0] == s.get_raw(X.GOAL_POSITION)  # holding its goal


async def test_sigquit_estops_every_servo_and_the_exit_leaves_them_so(tmp_path: Path) -> None:
    async with streaming_app(tmp_path) as (app, servos):
        app.send_signal(signal.SIGQUIT)
        await wait_until(lambda: not any(s.torque_enabled for s in servos))
        app.send_signal(signal.SIGINT)  # the exit must not undo the e-stop
        out = await rest_of(app)
        with anyio.fail_after(WAIT_S):
            assert await app.wait() == 130, out
        assert "on exit            hold: J1 e-stopped, J2 e-stopped" in out
        assert not any(s.torque_enabled for s in servos)
