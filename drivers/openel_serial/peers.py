"""Simulated serial peers on pseudo-terminals: a Dynamixel bus and an NMEA GPS.

Each peer owns the *master* end of a pty pair and answers like the device would; the
driver opens the *slave* tty through pyserial-asyncio-fast exactly as it would open
``/dev/ttyUSB0``, so tests and demos run the real serial stack end to end. The slave
is reached through a stable symlink (``peer.path``), like a udev
``/dev/serial/by-id`` link: unplugging closes the master (the driver's reads fail
with EIO, as for a vanished USB adapter) and plugging in again creates a new pty and
points the link at it, so the driver reopens the same path.

Peers are anyio tasks that wait on the master fd with ``anyio.wait_readable`` /
``wait_writable`` and use non-blocking ``os.read``/``os.write``: they never block the
event loop. A pty has no baud rate: bytes arrive as fast as the two ends run. By default a
peer runs on the event loop that enters it (the application's, in most tests);
:class:`PeerThread` hosts one on an event loop of its own in a thread, so that it goes on
running (and its clock on deciding, e.g., a watchdog's expiry) while the application's
loop is blocked, as a real device would.

* :class:`SimDynamixelBus` with :class:`SimServo` s: control table, trapezoidal
  profile moves (Profile Velocity/Acceleration), velocity mode ramping at Profile
  Acceleration, current mode, a mode change resetting the profile (as the e-manual says), Moving /
  Moving Status, Return Delay Time, read-only and EEPROM access rules, limit errors,
  REBOOT, error 3 (CRC error) for an instruction received damaged, the Bus Watchdog
  (98: the servo stops by itself when no instruction reached it for the set time, reads
  -1 and refuses goal writes until 0 is written); injection of status
  errors, hardware errors (alert bit; ``inject_fault``: overheating, from any thread),
  unresponsive servos, dropped and corrupted replies, damaged instructions, garbage bytes;
  unplug/plug; optionally, servos deaf to a driver whose tty is not at their Baud Rate (8).
* :class:`SimGps` (in :mod:`openel_serial.gps_peers`, re-exported here): GGA + RMC (``extended``: + GSA, GSV, GST) at ``rate_hz`` along a
  :class:`GpsPath`, answering MediaTek's ``$PMTK220`` rate command; injection of
  checksum errors, garbage, silence (pause), loss of fix (``inject_fault``) and unplug/plug.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from pathlib import Path
from typing import Any, ClassVar, Final

from openel_async.clock import Clock, default_clock
from openel_async.logs import get_logger
from openel_serial import dynamixel as dx
from openel_sim import profile as prof

from .buspeer import SimServoBus
from .gps_peers import GpsPath, SimGps
from .ptypeer import PeerThread, PtyPort

__all__ = [
    "GpsPath",
    "PeerThread",
    "PtyPort",
    "SimDynamixelBus",
    "SimGps",
    "SimServo",
]

log = get_logger(__name__)

X = dx.XSeries
TICKS_PER_S_PER_VELOCITY_UNIT: Final = dx.VELOCITY_UNIT_RPM / 60 * dx.TICKS_PER_REV
TICKS_PER_S2_PER_ACCELERATION_UNIT: Final = dx.ACCELERATION_UNIT_RPM2 / 3600 * dx.TICKS_PER_REV
PROFILE_ONGOING: Final = int(dx.MovingStatus.PROFILE_ONGOING)
IN_POSITION: Final = int(dx.MovingStatus.IN_POSITION)
UNLIMITED_ACCELERATION: Final = 1e7
"""Ticks/s^2 standing for Profile Acceleration 0 ("infinite")."""
COAST_ACCELERATION: Final = 20_000.0
"""Ticks/s^2 of the free rotor braking by friction once the torque is off."""
TABLE_SIZE: Final = 147
NS: Final = 1_000_000_000
_GOALS: Final = (X.GOAL_PWM, X.GOAL_CURRENT, X.GOAL_VELOCITY, X.GOAL_POSITION)
"""The goal items, read-only after a Bus Watchdog Error (the profile items are not)."""
_WATCHDOG_TRIPPED: Final = 0xFF
# -- Dynamixel ----------------------------------------------------------------------------


def _until(segments: list[prof.Segment], t_ns: int) -> list[prof.Segment]:
    """The part of a profile before ``t_ns``."""
    out = []
    for seg in segments:
        if seg.start_ns >= t_ns:
            break
        end = t_ns if seg.end_ns is None else min(seg.end_ns, t_ns)
        out.append(seg._replace(end_ns=end))
    return out


class SimServo:
    """A simulated Dynamixel X-series servo: control table and motion, in ticks.

    Motion is a closed-form profile (piecewise constant acceleration) evaluated at the
    time of each query: position moves follow the trapezoid of Profile Velocity and
    Profile Acceleration (0 = the velocity limit and an unbounded acceleration),
    velocity mode ramps at Profile Acceleration, current mode accelerates toward a
    speed proportional to Goal Current. Torque off lets the rotor coast to rest.

    ``baud_rate`` and ``return_delay_time`` are the EEPROM items' values (Baud Rate (8): 3
    is 1 Mbps, see :data:`~openel_serial.dynamixel.BAUD_RATES`; Return Delay Time (9): units
    of 2 us).
    """

    def __init__(
        self,
        dxl_id: int,
        *,
        model_number: int = 1020,  # XM430-W350
        firmware_version: int = 48,
        position: int = dx.CENTER_TICK,
        return_delay_time: int = 0,
        baud_rate: int = 3,
        velocity_limit: int = 200,
        profile_velocity: int = 0,
        profile_acceleration: int = 0,
        min_position: int = 0,
        max_position: int = 4095,
        current_limit: int = 1193,
        status_return_level: int = 2,
        boot_time: float = 0.02,
        clock: Clock | None = None,
    ) -> None:
        dx.Ping(dxl_id)  # validates the id
        if not 0 <= baud_rate < len(dx.BAUD_RATES):
            raise ValueError(f"Baud Rate (8) {baud_rate} is not in 0..{len(dx.BAUD_RATES) - 1}")
        if not 0 <= return_delay_time <= dx.RETURN_DELAY_MAX:
            raise ValueError(
                f"Return Delay Time (9) {return_delay_time} is not in 0..{dx.RETURN_DELAY_MAX}"
            )
        self.id = dxl_id
        self.clock: Clock = clock or default_clock()
        self.model_number = model_number
        self.firmware_version = firmware_version
        self.boot_time = boot_time
        self.table = bytearray(TABLE_SIZE)
        self._eeprom = {
            X.MODEL_NUMBER: model_number,
            X.FIRMWARE_VERSION: firmware_version,
            X.ID: dxl_id,
            X.BAUD_RATE: baud_rate,
            X.RETURN_DELAY_TIME: return_delay_time,
            X.OPERATING_MODE: dx.OperatingMode.POSITION,
            X.TEMPERATURE_LIMIT: 80,
            X.PWM_LIMIT: dx.PWM_FULL_SCALE,
            X.CURRENT_LIMIT: current_limit,
            X.VELOCITY_LIMIT: velocity_limit,
            X.MAX_POSITION_LIMIT: max_position,
            X.MIN_POSITION_LIMIT: min_position,
            X.SHUTDOWN: 0x34,
        }
        for item, value in self._eeprom.items():
            self._set(item, value)
        self._set(X.MOVING_THRESHOLD, 10)
        self._reset_ram(status_return_level, profile_velocity, profile_acceleration)
        now = self.clock.now_ns()
        self._segments = prof.hold(now, float(position))
        self._set(X.GOAL_POSITION, position)
        self._current = 0.0
        self._booting_until = 0
        self._plan_start = 0
        self._old_end = 0
        self.reaction_delay = 0.0
        """Seconds between a goal write and the start of the move; until then the servo
        reports its previous motion (a real servo's control loop lags the write)."""
        # Fault injection.
        self.responsive = True
        """False: the servo answers nothing (a cut cable, a wrong baud rate)."""
        self.injected_errors: list[int] = []
        """Error numbers put in the next status packets (the instruction is refused)."""
        self.instructions = 0
        self.crc_errors = 0
        """Instructions to this servo that failed their CRC (answered with CRC_ERROR)."""
        self.reboots = 0
        self._last_instruction_ns = now
        self.watchdog_trips = 0
        self.fault_requested: str | None = None
        """A fault asked for by :meth:`inject_fault`, not yet applied."""
        self.fault_reason: str | None = None
        """The reason of the last fault :meth:`inject_fault` applied."""
        self.watchdog_tripped_ns: int | None = None
        """When the Bus Watchdog last expired (the servo's clock), or None."""

    # -- control table ---------------------------------------------------------------
    def _set(self, item: dx.ControlItem, value: int) -> None:
        self.table[item.address : item.address + item.size] = item.encode(int(value))

    def get(self, item: dx.ControlItem) -> int:
        """A control-table item (present values are computed at the current time)."""
        if item.address >= X.REALTIME_TICK.address or item == X.BUS_WATCHDOG:
            self._refresh(self.clock.now_ns())
        return item.decode(bytes(self.table[item.address : item.address + item.size]))

    def _reset_ram(self, level: int = 2, profile_velocity: int = 0, profile_acc: int = 0) -> None:
        self.table[X.TORQUE_ENABLE.address :] = bytes(TABLE_SIZE - X.TORQUE_ENABLE.address)
        self._set(X.STATUS_RETURN_LEVEL, level)
        self._set(X.PROFILE_VELOCITY, profile_velocity)
        self._set(X.PROFILE_ACCELERATION, profile_acc)
        self._set(X.POSITION_P_GAIN, 800)
        self._set(X.PRESENT_INPUT_VOLTAGE, 120)
        self._set(X.PRESENT_TEMPERATURE, 30)

    @property
    def torque_enabled(self) -> bool:
        return bool(self.table[X.TORQUE_ENABLE.address])

    @property
    def baudrate(self) -> int:
        """The bit rate of Baud Rate (8): the only one at which the servo hears the host."""
        return dx.BAUD_RATES[self.table[X.BAUD_RATE.address]]

    @property
    def mode(self) -> int:
        return self.table[X.OPERATING_MODE.address]

    @property
    def hardware_error(self) -> int:
        return self.table[X.HARDWARE_ERROR_STATUS.address]

    @property
    def watchdog_tripped(self) -> bool:
        """Whether Bus Watchdog (98) reads -1 (Bus Watchdog Error) now."""
        self._check_watchdog(self.clock.now_ns())
        return self.table[X.BUS_WATCHDOG.address] == _WATCHDOG_TRIPPED

    def state(self) -> tuple[float, float]:
        """(position in ticks, velocity in ticks/s) now."""
        now = self.clock.now_ns()
        self._check_watchdog(now)
        p, v, _ = prof.evaluate(self._segments, now)
        return p, v

    # -- Bus Watchdog (98) -----------------------------------------------------------
    def _check_watchdog(self, now: int) -> None:
        """Expire the Bus Watchdog if no instruction reached the servo for its time.

        e-manual, Bus Watchdog (98): watched while the torque is on; at expiry the servo
        stops at once (the profile applied as 0: no deceleration ramp) and keeps its
        torque, the item reads -1 and the goal items become read-only until 0 is written.
        Expiry is decided on this servo's clock, whenever the servo is looked at: the
        motion is closed-form, so the stop happens at the expiry time however late that is.
        """
        setting = self.table[X.BUS_WATCHDOG.address]
        if not 1 <= setting <= dx.BUS_WATCHDOG_MAX or not self.torque_enabled:
            return
        expiry = self._last_instruction_ns + round(setting * dx.BUS_WATCHDOG_UNIT_S * NS)
        if now <= expiry:
            return
        p, _, _ = prof.evaluate(self._segments, expiry)
        self._segments = [*_until(self._segments, expiry), *prof.hold(expiry, p)]
        self._plan_start = self._old_end = expiry
        self._current = 0.0
        self.table[X.BUS_WATCHDOG.address] = _WATCHDOG_TRIPPED
        self.watchdog_trips += 1
        self.watchdog_tripped_ns = expiry
        log.debug("sim_dxl_bus_watchdog_expired", id=self.id, position=round(p))

    def arrival_ns(self) -> int:
        """When the current profile ends."""
        return prof.end_time(self._segments)

    # -- fault injection -------------------------------------------------------------
    def inject_status_error(self, error_number: int = dx.ErrorNumber.DATA_RANGE_ERROR) -> None:
        """The next status carries ``error_number`` and its instruction is refused."""
        self.injected_errors.append(int(error_number))

    def inject_hardware_error(self, bits: int = dx.HardwareError.OVERLOAD) -> None:
        """Hardware error: torque shut down, alert bit in every status until REBOOT."""
        now = self.clock.now_ns()
        self.table[X.HARDWARE_ERROR_STATUS.address] = int(bits)
        self._torque_off(now)

    # -- motion ----------------------------------------------------------------------
    def _amax(self) -> float:
        units = self.get_raw(X.PROFILE_ACCELERATION)
        return units * TICKS_PER_S2_PER_ACCELERATION_UNIT if units else UNLIMITED_ACCELERATION

    def _vmax(self) -> float:
        units = self.get_raw(X.PROFILE_VELOCITY) or self.get_raw(X.VELOCITY_LIMIT)
        return max(1, units) * TICKS_PER_S_PER_VELOCITY_UNIT

    def get_raw(self, item: dx.ControlItem) -> int:
        return item.decode(bytes(self.table[item.address : item.address + item.size]))

    def _torque_off(self, now: int) -> None:
        p, v, _ = prof.evaluate(self._segments, now)
        self._segments = prof.ramp(now, p, v, 0.0, COAST_ACCELERATION)
        self._current = 0.0
        self.table[X.TORQUE_ENABLE.address] = 0

    def _replan(self, now: int) -> None:
        """Start the move the goal items and the mode ask for (torque on).

        The new profile starts ``reaction_delay`` after ``now``; until then the old one
        goes on and the present values (Moving included) still describe it.
        """
        if not self.torque_enabled or self.hardware_error:
            return
        if self.table[X.BUS_WATCHDOG.address] == _WATCHDOG_TRIPPED:
            return  # stopped by the Bus Watchdog: no motion until cleared and a new goal
        start = now + round(self.reaction_delay * NS)
        old = self._segments
        p, v, _ = prof.evaluate(old, start)
        mode = self.mode
        if mode in (3, 4, 5):
            goal = float(self.get_raw(X.GOAL_POSITION))
            plan = prof.trapezoid(start, p, v, goal, self._vmax(), self._amax())
            self._current = 0.0
        elif mode == dx.OperatingMode.VELOCITY:
            goal_v = self.get_raw(X.GOAL_VELOCITY) * TICKS_PER_S_PER_VELOCITY_UNIT
            plan = prof.ramp(start, p, v, goal_v, self._amax())
            self._current = 0.0
        elif mode == dx.OperatingMode.CURRENT:
            current = self.get_raw(X.GOAL_CURRENT)
            limit = max(1, self.get_raw(X.CURRENT_LIMIT))
            speed = current / limit * self.get_raw(X.VELOCITY_LIMIT) * TICKS_PER_S_PER_VELOCITY_UNIT
            plan = prof.ramp(start, p, v, speed, self._amax())
            self._current = float(current)
        else:
            return
        if start > now:
            self._old_end = prof.end_time(old)
            plan = [*_until(old, start), *plan]
        self._plan_start = start
        self._segments = plan

    def _refresh(self, now: int) -> None:
        """Write the present values (120..143) for time ``now`` into the table."""
        self._check_watchdog(now)
        p, v, a = prof.evaluate(self._segments, now)
        if now < self._plan_start:  # the servo has not reacted to the latest goal yet
            ongoing = now < self._old_end
        else:
            ongoing = now < prof.end_time(self._segments)
        table = self.table
        velocity = round(v / TICKS_PER_S_PER_VELOCITY_UNIT)
        (threshold,) = struct.unpack_from("<I", table, X.MOVING_THRESHOLD.address)
        moving = ongoing or abs(velocity) > threshold
        mode = table[X.OPERATING_MODE.address]
        (goal,) = struct.unpack_from("<i", table, X.GOAL_POSITION.address)
        (profile_acc, profile_vel) = struct.unpack_from(
            "<II", table, X.PROFILE_ACCELERATION.address
        )
        status = PROFILE_ONGOING if ongoing else 0
        if mode in (3, 4, 5) and abs(goal - p) <= 4 and not ongoing:
            status |= IN_POSITION
        if profile_vel and profile_acc:
            status |= 0x30  # trapezoidal profile
        current = self._current if mode == 0 else a / TICKS_PER_S2_PER_ACCELERATION_UNIT / 50
        position = round(p)
        struct.pack_into(
            "<HBBhhiiii",
            table,
            X.REALTIME_TICK.address,
            (now // 1_000_000) % 32768,
            int(moving),
            status,
            0,  # Present PWM
            max(-32768, min(32767, round(current))),
            velocity,
            position,
            velocity,  # Velocity Trajectory
            position,  # Position Trajectory
        )

    # -- instructions ----------------------------------------------------------------
    def _status(self, error: int = 0, params: bytes = b"") -> dx.Status:
        if self.hardware_error:
            error |= dx.ALERT_BIT
        return dx.Status(self.id, error, params)

    def _read(self, address: int, length: int) -> dx.Status:
        if address + length > TABLE_SIZE or length == 0:
            return self._status(dx.ErrorNumber.DATA_LENGTH_ERROR)
        self._refresh(self.clock.now_ns())
        return self._status(0, bytes(self.table[address : address + length]))

    def _write_error(self, address: int, data: bytes) -> int:
        end = address + len(data)
        if end > TABLE_SIZE or not data:
            return dx.ErrorNumber.DATA_LENGTH_ERROR
        read_only = (
            address < X.ID.address  # model number, model information, firmware version
            or address <= X.REGISTERED_INSTRUCTION.address < end
            or address <= X.HARDWARE_ERROR_STATUS.address < end
            or end > X.REALTIME_TICK.address  # present values
        )
        if read_only:
            return dx.ErrorNumber.ACCESS_ERROR
        if address < X.TORQUE_ENABLE.address and self.torque_enabled:
            return dx.ErrorNumber.ACCESS_ERROR  # EEPROM is locked while the torque is on
        watchdog = X.BUS_WATCHDOG.address
        if address <= watchdog < end:
            value = X.BUS_WATCHDOG.decode(data[watchdog - address : watchdog - address + 1])
            tripped = self.table[watchdog] == _WATCHDOG_TRIPPED
            if not 0 <= value <= dx.BUS_WATCHDOG_MAX or (tripped and value != 0):
                return dx.ErrorNumber.DATA_RANGE_ERROR  # only 0 clears a Bus Watchdog Error
        elif self.table[watchdog] == _WATCHDOG_TRIPPED and any(
            address < goal.address + goal.size and end > goal.address for goal in _GOALS
        ):
            return dx.ErrorNumber.DATA_RANGE_ERROR  # goals are read-only after expiry
        goal = X.GOAL_POSITION
        if address <= goal.address and end >= goal.address + goal.size and self.mode == 3:
            offset = goal.address - address
            value = goal.decode(data[offset : offset + goal.size])
            low, high = self.get_raw(X.MIN_POSITION_LIMIT), self.get_raw(X.MAX_POSITION_LIMIT)
            if not low <= value <= high:
                return dx.ErrorNumber.DATA_LIMIT_ERROR
        velocity = X.GOAL_VELOCITY
        if address <= velocity.address and end >= velocity.address + velocity.size:
            offset = velocity.address - address
            value = velocity.decode(data[offset : offset + velocity.size])
            if abs(value) > self.get_raw(X.VELOCITY_LIMIT):
                return dx.ErrorNumber.DATA_LIMIT_ERROR
        return 0

    def _write(self, address: int, data: bytes) -> int:
        error = self._write_error(address, data)
        if error:
            return error
        now = self.clock.now_ns()
        torque_before = self.torque_enabled
        mode_before = self.mode
        end = address + len(data)
        self.table[address:end] = data
        if address <= X.OPERATING_MODE.address < end and self.mode != mode_before:
            # e-manual, Operating Mode (11): a mode change resets the profile generator.
            self._set(X.PROFILE_VELOCITY, 0)
            self._set(X.PROFILE_ACCELERATION, 0)
            self._set(X.GOAL_PWM, self.get_raw(X.PWM_LIMIT))
        torque_item = X.TORQUE_ENABLE.address
        if address <= torque_item < end:
            if self.hardware_error:
                self.table[torque_item] = 0  # no torque until rebooted
            requested = bool(self.table[torque_item])
            if torque_before and not requested:
                self._torque_off(now)
            elif requested and not torque_before:
                self._replan(now)
        if end > X.GOAL_PWM.address and address < X.GOAL_POSITION.address + 4:
            self._replan(now)  # a goal or profile item changed
        return 0

    def _reboot(self) -> None:
        now = self.clock.now_ns()
        p, _, _ = prof.evaluate(self._segments, now)
        self._segments = prof.ramp(now, p, 0.0, 0.0, COAST_ACCELERATION)
        self._reset_ram()
        self._set(X.GOAL_POSITION, round(p))
        self._current = 0.0
        self._booting_until = now + round(self.boot_time * NS)
        self.reboots += 1

    def _answers(self, msg: dx.DynamixelMessage) -> bool:
        """Whether ``msg`` asks this servo for a status (Status Return Level applied)."""
        level = self.table[X.STATUS_RETURN_LEVEL.address]
        if isinstance(msg, dx.Ping):
            return True
        if isinstance(msg, dx.SyncRead):
            return self.id in msg.ids and level >= 1
        if isinstance(msg, dx.SyncWrite) or getattr(msg, "id", None) == dx.BROADCAST_ID:
            return False
        return level >= (1 if isinstance(msg, dx.Read) else 2)

    def handle_corrupt(self, packet: dx.CorruptPacket) -> dx.Status | None:
        """An instruction that failed its CRC: CRC_ERROR if it was addressed to this servo.

        Nothing is executed. Like any status, the reply obeys Status Return Level
        (judged from the instruction byte as received); broadcasts get no reply.
        """
        self._apply_requested_fault()
        if not self.responsive or self.clock.now_ns() < self._booting_until:
            return None
        if packet.id != self.id or packet.instruction == dx.Instruction.STATUS:
            return None
        self.crc_errors += 1
        level = self.table[X.STATUS_RETURN_LEVEL.address]
        if packet.instruction == dx.Instruction.PING:
            needed = 0
        else:
            needed = 1 if packet.instruction == dx.Instruction.READ else 2
        if level < needed:
            return None
        return self._status(dx.ErrorNumber.CRC_ERROR)

    def inject_fault(self, reason: str) -> None:
        """Overheat (``openel_async.rig.FaultInjection``): Hardware Error Status bit 2, the
        torque shut down and the alert bit in every status until REBOOT, as the servo's
        Shutdown (63) setting does. Callable from any thread: the request is applied by the
        thread serving the servo when it handles its next instruction (the host's next
        poll)."""
        self.fault_requested = reason

    def _apply_requested_fault(self) -> None:
        reason = self.fault_requested
        if reason is not None:
            self.fault_requested = None
            self.fault_reason = reason
            log.info("sim_dxl_fault_injected", id=self.id, reason=reason)
            self._set(X.PRESENT_TEMPERATURE, self.get_raw(X.TEMPERATURE_LIMIT) + 1)
            self.inject_hardware_error(dx.HardwareError.OVERHEATING)

    def handle(self, msg: dx.DynamixelMessage) -> dx.Status | None:
        """Execute one instruction; the status to send back, if any."""
        self._apply_requested_fault()
        if not self.responsive or self.clock.now_ns() < self._booting_until:
            return None
        targeted = isinstance(msg, dx.SyncRead | dx.SyncWrite) or getattr(msg, "id", None) in (
            self.id,
            dx.BROADCAST_ID,
        )
        if not targeted or isinstance(msg, dx.Status):
            return None
        if isinstance(msg, dx.SyncRead) and self.id not in msg.ids:
            return None
        self.instructions += 1
        now = self.clock.now_ns()
        self._check_watchdog(now)  # expired before this packet arrived?
        self._last_instruction_ns = now  # any instruction packet feeds the watchdog
        answers = self._answers(msg)
        if answers and self.injected_errors:
            return self._status(self.injected_errors.pop(0))  # refused, not executed
        status: dx.Status
        match msg:
            case dx.Ping():
                status = self._status(
                    0, struct.pack("<HB", self.model_number, self.firmware_version)
                )
            case dx.Read() | dx.SyncRead():
                status = self._read(msg.address, msg.length)
            case dx.RegWrite():
                status = self._status(dx.ErrorNumber.INSTRUCTION_ERROR)  # not simulated
            case dx.Write():
                status = self._status(self._write(msg.address, msg.data))
            case dx.SyncWrite():
                for item in msg.items:
                    if item.id == self.id:
                        self._write(msg.address, item.data)
                return None
            case dx.Reboot():
                self._reboot()
                status = self._status()
            case _:
                status = self._status(dx.ErrorNumber.INSTRUCTION_ERROR)
        return status if answers else None


class SimDynamixelBus(SimServoBus[SimServo, dx.DynamixelMessage]):
    """A Dynamixel bus behind a pty: the servos answer the driver's instruction packets.

    ``servos`` are :class:`SimServo` s or ids (default servos). Replies to one
    instruction (several for a SYNC READ, in the order of its id list) are sent together
    after the servos' Return Delay Times. Everything the driver sent is kept in
    ``received`` (raw bytes) and ``instructions`` (decoded).

    ``check_baudrate``: a servo hears the driver only when the bit rate the driver set on
    the tty (its termios settings, :meth:`PtyPort.baudrate`) is the servo's Baud Rate (8),
    as on a real bus (``baud_mismatches`` counts the packets a servo missed so); off by
    default (a pty carries bytes at any setting).
    """

    return_delay_address: ClassVar[int] = X.RETURN_DELAY_TIME.address
    return_delay_unit_s: ClassVar[float] = dx.RETURN_DELAY_UNIT_S

    def __init__(
        self,
        servos: Iterable[SimServo | int],
        *,
        path: str | Path | None = None,
        clock: Clock | None = None,
        check_baudrate: bool = False,
    ) -> None:
        super().__init__(path=path, clock=clock, check_baudrate=check_baudrate)
        self.servos: dict[int, SimServo] = {}
        for servo in servos:
            if isinstance(servo, int):
                servo = SimServo(servo, clock=self.clock)
            if servo.id in self.servos:
                raise ValueError(f"two simulated servos with id {servo.id}")
            self.servos[servo.id] = servo
        self.corrupt_requests = 0
        """Instruction packets still to be received as if damaged on the wire (CRC fails)."""

    def __getitem__(self, dxl_id: int) -> SimServo:
        return self.servos[dxl_id]

    def inject_garbage(self, data: bytes = b"\x00\x13\xff\xff\xfd\x00\xaa\x55\xff") -> None:
        """Send noise to the driver now (a glitch on the line)."""
        super().inject_garbage(data)

    def new_parser(self) -> dx.PacketParser:
        return dx.PacketParser()

    def encode_status(self, status: Any) -> bytes:
        return dx.encode(status)

    async def receive(self, msg: dx.DynamixelMessage | dx.CorruptPacket) -> None:
        """A packet whose CRC failed is answered with CRC_ERROR when addressed to a servo."""
        if self.corrupt_requests and not isinstance(msg, dx.CorruptPacket):
            self.corrupt_requests -= 1  # damaged on the wire: the CRC fails
            packet = dx.encode(msg)
            msg = dx.CorruptPacket(packet[4], packet[7], len(packet) - 7)
        if isinstance(msg, dx.CorruptPacket):
            self.corrupt_instructions += 1
        else:
            self.log_instruction(msg)
        await self._answer(msg)

    async def _answer(self, msg: dx.DynamixelMessage | dx.CorruptPacket) -> None:
        if isinstance(msg, dx.CorruptPacket):
            servo = self.servos.get(msg.id)
            order = [] if servo is None else [servo]
        elif isinstance(msg, dx.SyncRead):
            order = [self.servos[i] for i in msg.ids if i in self.servos]
        elif isinstance(msg, dx.SyncWrite) or getattr(msg, "id", None) == dx.BROADCAST_ID:
            order = [self.servos[i] for i in sorted(self.servos)]  # a broadcast PING: by id
        else:
            servo = self.servos.get(getattr(msg, "id", -1))
            order = [] if servo is None else [servo]
        if isinstance(msg, dx.CorruptPacket):
            corrupt = msg
            await self.send_replies(order, lambda servo: servo.handle_corrupt(corrupt))
        else:
            message = msg
            await self.send_replies(order, lambda servo: servo.handle(message))
