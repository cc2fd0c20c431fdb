"""A simulated Feetech STS bus behind a pty: :class:`SimFeetechBus` with :class:`SimStsServo` s.

The driver (ours, or the vendor's ``scservo_sdk``) opens the pty's path as it would open
``/dev/ttyACM0``; the servos answer instruction packets with the STS3215's control table
(:class:`openel_serial.feetech.STS`), timing and behaviour:

* PING, READ, WRITE, REG_WRITE + ACTION, SYNC READ (statuses in the order of the id list, after
  each servo's Return Delay (7), 2 us units), SYNC WRITE, RESET (factory values, id kept);
  Response Status Level (8) 0: a status only for PING and READ (and SYNC READ); broadcast
  instructions are never answered except PING.
* Motion in steps, closed-form (:mod:`openel_sim.profile`): position mode (33 = 0) moves to Goal
  Position (42) at Goal Speed (46; 0 = the model's top speed) and Acceleration (41, 100 steps/s^2;
  0 = at once), clamped to the Min/Max Angle Limits (9, 11; both 0 = no limit); wheel mode (1)
  ramps to Goal Speed (sign-magnitude, bit 15); torque off lets the rotor coast to rest.
  Present Position = the rotor's steps - Homing Offset (31, sign-magnitude bit 11), wrapped
  into 0..4095; Torque Enable (40) = 128 sets the offset so that it reads 2048.
* Load (60, 0.1 % of stall torque, sign in bit 10): ``external_load`` plus what the
  acceleration takes; Present Current (69) follows it; Temperature (63) rises toward
  ``ambient + 40 C x |load|`` with a time constant of ``thermal_time_constant``;
  Voltage (62) is ``supply_voltage``.
* Alarms (the status error byte and Servo Status (65), :class:`~openel_serial.feetech.StatusError`):
  VOLTAGE while the supply is outside Min/Max Voltage (15, 14); OVERHEAT above Max Temperature
  (13); OVERLOAD latched when |load| exceeds Overload Torque (36, %) for Protection Time
  (35, 10 ms) -- or at once by :meth:`SimStsServo.inject_fault`. An alarm whose bit is in
  Unloading Condition (19) turns the torque off; Torque Enable = 1 is refused while one is in
  force (overload: cleared by that write once the load is gone).
* Lock (55, power-up 1): EEPROM writes (addresses 0..39) take effect at once and are kept by
  :meth:`SimStsServo.power_cycle` only when written with Lock = 0.
* Malformed input, as the servos (and the vendor's SDK, which then times out) treat it: a
  packet whose checksum fails is dropped without a reply (a servo cannot know whom a damaged
  packet was for, and its status has no error bit for it); an unknown instruction, a READ beyond
  the table or a truncated packet get no reply either; writes to read-only registers are
  ignored (the status says nothing).
* ``responsive = False`` makes a servo silent (unplugged from the daisy chain); the whole bus
  unplugs with :meth:`SimFeetechBus.unplug` (the driver sees EIO). ``check_baudrate``: a servo
  hears the driver only when the tty is at its Baud Rate (6).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable
from pathlib import Path
from typing import Any, ClassVar, Final

from openel_async.clock import Clock, default_clock
from openel_async.logs import get_logger
from openel_serial import feetech as ft
from openel_sim import profile as prof

from .buspeer import SimServoBus

__all__ = ["SimFeetechBus", "SimStsServo"]

log = get_logger(__name__)

S = ft.STS
NS: Final = 1_000_000_000
TOP_SPEED: Final = 3073
"""Steps/s of an unloaded STS3215 (0.222 s / 60 deg at 7.4 V: 45 rpm)."""
UNLIMITED_ACCELERATION: Final = 1e6
COAST_ACCELERATION: Final = 20_000.0
EEPROM_END: Final = 40
_UNLOADING_DEFAULT: Final = int(
    ft.StatusError.OVERHEAT | ft.StatusError.OVERCURRENT | ft.StatusError.OVERLOAD
)


class SimStsServo:
    """A simulated STS3215 (see the module docstring); ``position`` in steps (rotor)."""

    def __init__(
        self,
        servo_id: int,
        *,
        model_number: int = ft.STS3215_MODEL,
        position: float = ft.CENTER_TICK,
        baud_rate: int = 0,
        return_delay: int = 0,
        response_status_level: int = 1,
        min_angle: int = 0,
        max_angle: int = 4095,
        homing_offset: int = 0,
        top_speed: float = TOP_SPEED,
        clock: Clock | None = None,
    ) -> None:
        ft.Ping(servo_id)
        if not 0 <= baud_rate < len(ft.BAUD_RATES):
            raise ValueError(f"Baud Rate (6) {baud_rate} is not in 0..{len(ft.BAUD_RATES) - 1}")
        if not 0 <= return_delay <= ft.RETURN_DELAY_MAX:
            raise ValueError(f"Return Delay (7) {return_delay} is not in 0..{ft.RETURN_DELAY_MAX}")
        self.clock: Clock = clock or default_clock()
        self.top_speed = float(top_speed)
        self.table = bytearray(S.TABLE_SIZE)
        for item, value in (
            (S.FIRMWARE_MAJOR, 3),
            (S.FIRMWARE_MINOR, 10),
            (S.MODEL_NUMBER, model_number),
            (S.ID, servo_id),
            (S.BAUD_RATE, baud_rate),
            (S.RETURN_DELAY, return_delay),
            (S.RESPONSE_STATUS_LEVEL, response_status_level),
            (S.MIN_ANGLE_LIMIT, min_angle),
            (S.MAX_ANGLE_LIMIT, max_angle),
            (S.MAX_TEMPERATURE, 70),
            (S.MAX_VOLTAGE, 140),
            (S.MIN_VOLTAGE, 40),
            (S.MAX_TORQUE, 1000),
            (S.UNLOADING_CONDITION, _UNLOADING_DEFAULT),
            (S.LED_ALARM_CONDITION, 47),
            (S.P_COEFFICIENT, 32),
            (S.I_COEFFICIENT, 0),
            (S.CW_DEAD_ZONE, 1),
            (S.CCW_DEAD_ZONE, 1),
            (S.PROTECTION_CURRENT, 500),
            (S.ANGULAR_RESOLUTION, 1),
            (S.HOMING_OFFSET, homing_offset),
            (S.PROTECTIVE_TORQUE, 20),
            (S.PROTECTION_TIME, 200),
            (S.OVERLOAD_TORQUE, 80),
        ):
            self._set(item, value)
        self._factory = bytes(self.table[:EEPROM_END])
        self._persisted = bytes(self.table[:EEPROM_END])
        now = self.clock.now_ns()
        self._segments = prof.hold(now, float(position))
        self._reset_ram(now)
        self.external_load = 0.0
        """Load (0.1 % of stall torque) the arm puts on the servo (gravity, a grip)."""
        self.supply_voltage = 120
        """The supply, 0.1 V (Present Voltage)."""
        self.ambient = 25.0
        self.thermal_time_constant = 120.0
        self._temperature = self.ambient
        self._thermal_ns = now
        self._overload_since: int | None = None
        self._latched = 0
        """OVERLOAD / OVERCURRENT / ANGLE bits latched until the torque is enabled again."""
        self._registered: tuple[int, bytes] | None = None
        self.responsive = True
        """False: the servo answers nothing (unplugged from the chain)."""
        self.instructions = 0
        self.checksum_errors = 0
        self.fault_requested: str | None = None
        self.fault_reason: str | None = None
        self._fault_lock = threading.Lock()

    # -- control table ---------------------------------------------------------------
    @property
    def id(self) -> int:
        return self.table[S.ID.address]

    def _set(self, item: ft.ControlItem, value: int) -> None:
        self.table[item.address : item.address + item.size] = item.encode(int(value))

    def get_raw(self, item: ft.ControlItem) -> int:
        return item.decode(bytes(self.table[item.address : item.address + item.size]))

    def get(self, item: ft.ControlItem) -> int:
        """A register, present values computed for now."""
        self._refresh(self.clock.now_ns())
        return self.get_raw(item)

    def _reset_ram(self, now: int) -> None:
        self.table[EEPROM_END:] = bytes(S.TABLE_SIZE - EEPROM_END)
        self._set(S.LOCK, 1)
        self._set(S.TORQUE_LIMIT, self.get_raw(S.MAX_TORQUE))
        present = self._present_position(now)
        self._set(S.GOAL_POSITION, present)

    @property
    def torque_enabled(self) -> bool:
        return bool(self.table[S.TORQUE_ENABLE.address])

    @property
    def mode(self) -> int:
        return self.table[S.OPERATING_MODE.address]

    @property
    def baudrate(self) -> int:
        return ft.BAUD_RATES[self.table[S.BAUD_RATE.address] % len(ft.BAUD_RATES)]

    @property
    def locked(self) -> bool:
        return bool(self.table[S.LOCK.address])

    def rotor(self) -> tuple[float, float]:
        """(rotor position in steps, velocity in steps/s) now."""
        p, v, _ = prof.evaluate(self._segments, self.clock.now_ns())
        return p, v

    def set_rotor(self, position: float) -> None:
        """Move the rotor by hand to ``position`` steps (torque off: a person moving the joint)."""
        now = self.clock.now_ns()
        self._segments = prof.hold(now, float(position))

    def power_cycle(self) -> None:
        """Power off and on: EEPROM as last kept (written with Lock 0), RAM at its defaults."""
        now = self.clock.now_ns()
        p, _ = self.rotor()
        self.table[:EEPROM_END] = self._persisted
        self._segments = prof.hold(now, p)
        self._reset_ram(now)
        self._latched = 0
        self._registered = None

    # -- faults ---------------------------------------------------------------------------
    def inject_fault(self, reason: str) -> None:
        """Trip as the servo does (``openel_async.rig.FaultInjection``), from any thread:
        ``reason`` naming "load" -> OVERLOAD, "volt" -> the supply drops below Min Voltage
        (15), anything else -> OVERHEAT (the temperature jumps above Max Temperature (13)).
        Applied by the thread serving the servo at its next instruction."""
        with self._fault_lock:
            self.fault_requested = reason

    def _apply_requested_fault(self, now: int) -> None:
        with self._fault_lock:
            reason, self.fault_requested = self.fault_requested, None
        if reason is None:
            return
        self.fault_reason = reason
        log.info("sim_feetech_fault_injected", id=self.id, reason=reason)
        text = reason.lower()
        if "load" in text:
            self._latched |= ft.StatusError.OVERLOAD
        elif "volt" in text:
            self.supply_voltage = max(0, self.get_raw(S.MIN_VOLTAGE) - 5)
        else:
            self._temperature = self.get_raw(S.MAX_TEMPERATURE) + 5.0
            self._thermal_ns = now

    def clear_faults(self) -> None:
        """Cool down, restore the supply, drop the latched alarms (a pause and a power check)."""
        self._temperature = self.ambient
        self._thermal_ns = self.clock.now_ns()
        self.supply_voltage = 120
        self.external_load = 0.0
        self._latched = 0
        self._overload_since = None

    def alarms(self, now: int | None = None) -> int:
        """The :class:`~openel_serial.feetech.StatusError` bits in force."""
        self._refresh(self.clock.now_ns() if now is None else now)
        return self.table[S.SERVO_STATUS.address]

    def _alarm_bits(self) -> int:
        bits = self._latched
        voltage = self.supply_voltage
        if not self.get_raw(S.MIN_VOLTAGE) <= voltage <= self.get_raw(S.MAX_VOLTAGE):
            bits |= ft.StatusError.VOLTAGE
        if self._temperature > self.get_raw(S.MAX_TEMPERATURE):
            bits |= ft.StatusError.OVERHEAT
        return int(bits)

    # -- motion ----------------------------------------------------------------------
    def _offset(self) -> int:
        return self.get_raw(S.HOMING_OFFSET)

    def _present_position(self, now: int) -> int:
        p, _, _ = prof.evaluate(self._segments, now)
        return round(p - self._offset()) % ft.TICKS_PER_REV

    def _amax(self) -> float:
        units = self.table[S.ACCELERATION.address]
        return units * ft.ACCELERATION_UNIT_STEPS_S2 if units else UNLIMITED_ACCELERATION

    def _torque_off(self, now: int) -> None:
        p, v, _ = prof.evaluate(self._segments, now)
        self._segments = prof.ramp(now, p, v, 0.0, COAST_ACCELERATION)
        self.table[S.TORQUE_ENABLE.address] = 0

    def _replan(self, now: int) -> None:
        if not self.torque_enabled:
            return
        p, v, _ = prof.evaluate(self._segments, now)
        speed = self.get_raw(S.GOAL_SPEED)
        if self.mode == ft.OperatingMode.WHEEL:
            target = max(-self.top_speed, min(self.top_speed, float(speed)))
            self._segments = prof.ramp(now, p, v, target, self._amax())
            return
        if self.mode != ft.OperatingMode.POSITION:
            self._segments = prof.hold(now, p)
            return
        goal = self.get_raw(S.GOAL_POSITION)
        low, high = self.get_raw(S.MIN_ANGLE_LIMIT), self.get_raw(S.MAX_ANGLE_LIMIT)
        if low or high:
            goal = max(low, min(high, goal))
        # The goal is in the present-position frame: to the rotor's, the nearest turn.
        present = p - self._offset()
        base = present - (present % ft.TICKS_PER_REV)
        rotor_goal = base + goal + self._offset()
        vmax = min(self.top_speed, abs(speed)) if speed else self.top_speed
        self._segments = prof.trapezoid(now, p, v, float(rotor_goal), max(1.0, vmax), self._amax())

    def _refresh(self, now: int) -> None:
        """Present values (56..70) and alarms for time ``now``."""
        self._apply_requested_fault(now)
        _, v, a = prof.evaluate(self._segments, now)
        load = (
            self.external_load + (a / max(self._amax(), 1.0)) * 300 if self.torque_enabled else 0.0
        )
        if self.torque_enabled and v:
            load += math.copysign(30.0, v)
        load = max(-1000.0, min(1000.0, load))
        # Temperature: first order toward ambient + 40 C at full load.
        dt = (now - self._thermal_ns) / NS
        if dt > 0:
            target = self.ambient + 40.0 * abs(load) / 1000
            self._temperature = target + (self._temperature - target) * math.exp(
                -dt / self.thermal_time_constant
            )
            self._thermal_ns = now
        # Overload protection: |load| above Overload Torque (36, %) for Protection Time (35).
        if self.torque_enabled and abs(load) > self.table[S.OVERLOAD_TORQUE.address] * 10:
            if self._overload_since is None:
                self._overload_since = now
            elif now - self._overload_since >= self.table[S.PROTECTION_TIME.address] * 10_000_000:
                self._latched |= ft.StatusError.OVERLOAD
        else:
            self._overload_since = None
        bits = self._alarm_bits()
        if bits & self.table[S.UNLOADING_CONDITION.address] and self.torque_enabled:
            self._torque_off(now)
            _, v, _ = prof.evaluate(self._segments, now)
        moving = abs(v) > 1.0 or now < prof.end_time(self._segments)
        speed = round(v)
        current = round(abs(load) * 2.0 / 1000 / ft.CURRENT_UNIT_A) if self.torque_enabled else 0
        for item, value in (
            (S.PRESENT_POSITION, self._present_position(now)),
            (S.PRESENT_SPEED, max(-32767, min(32767, speed))),
            (S.PRESENT_LOAD, round(load)),
            (S.PRESENT_VOLTAGE, self.supply_voltage),
            (S.PRESENT_TEMPERATURE, max(0, min(255, round(self._temperature)))),
            (S.SERVO_STATUS, bits),
            (S.MOVING, int(moving and self.torque_enabled)),
            (S.PRESENT_CURRENT, current),
        ):
            self._set(item, value)

    # -- instructions ----------------------------------------------------------------
    def _status(self, now: int, params: bytes = b"") -> ft.Status:
        return ft.Status(self.id, self.alarms(now), params)

    def _read(self, now: int, address: int, length: int) -> ft.Status | None:
        if length == 0 or address + length > S.TABLE_SIZE:
            return None  # no reply (documented in the module docstring)
        self._refresh(now)
        return self._status(now, bytes(self.table[address : address + length]))

    def _write(self, now: int, address: int, data: bytes) -> None:
        end = address + len(data)
        if not data or end > S.TABLE_SIZE:
            return
        self._refresh(now)
        torque_before = self.torque_enabled
        offset_before = self._offset()
        for i, byte in enumerate(data, start=address):
            if _writable(i):
                self.table[i] = byte
        if address < EEPROM_END and not self.locked:
            self._persisted = bytes(self.table[:EEPROM_END])
        torque = S.TORQUE_ENABLE.address
        if address <= torque < end:
            requested = self.table[torque]
            if requested == 128:  # make the present position read 2048
                p, _, _ = prof.evaluate(self._segments, now)
                offset = max(-2047, min(2047, round(p) - ft.CENTER_TICK))
                self._set(S.HOMING_OFFSET, offset)
                if not self.locked:
                    self._persisted = bytes(self.table[:EEPROM_END])
                self.table[torque] = int(torque_before)
                self._set(S.GOAL_POSITION, self._present_position(now))
            elif requested:
                self.table[torque] = 1
                if not torque_before:
                    self._latched &= ~int(ft.StatusError.OVERLOAD | ft.StatusError.OVERCURRENT)
                    self._overload_since = None
                    if self._alarm_bits() & self.table[S.UNLOADING_CONDITION.address]:
                        self.table[torque] = 0  # refused while the alarm is in force
                    else:
                        self._replan(now)
            elif torque_before:
                self._torque_off(now)
        goals = S.ACCELERATION.address <= end - 1 and address <= S.GOAL_SPEED.address + 1
        mode = address <= S.OPERATING_MODE.address < end
        if goals or mode or self._offset() != offset_before:
            self._replan(now)

    def handle(self, msg: ft.FeetechMessage) -> ft.Status | None:
        """Execute one instruction; the status to send back, if any."""
        now = self.clock.now_ns()
        self._apply_requested_fault(now)
        if not self.responsive or isinstance(msg, ft.Status):
            return None
        my_id = self.id
        if isinstance(msg, ft.SyncRead):
            if my_id not in msg.ids:
                return None
            self.instructions += 1
            return self._read(now, msg.address, msg.length)
        if isinstance(msg, ft.SyncWrite):
            for item in msg.items:
                if item.id == my_id:
                    self.instructions += 1
                    self._write(now, msg.address, item.data)
            return None
        if msg.id not in (my_id, ft.BROADCAST_ID):
            return None
        self.instructions += 1
        broadcast = msg.id == ft.BROADCAST_ID
        level = self.table[S.RESPONSE_STATUS_LEVEL.address]
        status: ft.Status | None
        match msg:
            case ft.Ping():
                return self._status(now)
            case ft.Read():
                return None if broadcast else self._read(now, msg.address, msg.length)
            case ft.RegWrite():  # before Write: a RegWrite is one
                self._registered = (msg.address, msg.data)
                status = self._status(now)
            case ft.Write():
                self._write(now, msg.address, msg.data)
                status = self._status(now)
            case ft.Action():
                registered, self._registered = self._registered, None
                if registered is not None:
                    self._write(now, *registered)
                status = self._status(now)
            case ft.Reset():
                servo_id = my_id
                self.table[:EEPROM_END] = self._factory
                self._set(S.ID, servo_id)
                self._persisted = bytes(self.table[:EEPROM_END])
                self._reset_ram(now)
                status = self._status(now)
            case _:
                return None
        return None if broadcast or level == 0 else status


def _writable(address: int) -> bool:
    """Whether a WRITE changes ``address`` (model and firmware, present values: no)."""
    if address < S.ID.address:
        return False
    return not S.PRESENT_POSITION.address <= address < S.TABLE_SIZE


class SimFeetechBus(SimServoBus[SimStsServo, ft.FeetechMessage]):
    """A Feetech bus behind a pty: the servos answer the driver's instruction packets.

    ``servos``: :class:`SimStsServo` s or ids. The statuses to one instruction (several for a
    SYNC READ, in the order of its ids) are sent together after the servos' Return Delays.
    What the driver sent is kept in ``received``/``instructions`` (``keep_log``); a packet
    whose checksum failed is dropped unanswered (``corrupt_instructions``).
    """

    return_delay_address: ClassVar[int] = S.RETURN_DELAY.address
    return_delay_unit_s: ClassVar[float] = ft.RETURN_DELAY_UNIT_S

    def __init__(
        self,
        servos: Iterable[SimStsServo | int],
        *,
        path: str | Path | None = None,
        clock: Clock | None = None,
        check_baudrate: bool = False,
    ) -> None:
        super().__init__(path=path, clock=clock, check_baudrate=check_baudrate)
        self.servos: list[SimStsServo] = []
        for servo in servos:
            if isinstance(servo, int):
                servo = SimStsServo(servo, clock=self.clock)
            if any(s.id == servo.id for s in self.servos):
                raise ValueError(f"two simulated servos with id {servo.id}")
            self.servos.append(servo)

    def __getitem__(self, servo_id: int) -> SimStsServo:
        for servo in self.servos:
            if servo.id == servo_id:
                return servo
        raise KeyError(servo_id)

    def inject_garbage(self, data: bytes = b"\x00\xff\xff\xff\x13\xaa") -> None:
        """Send noise to the driver now (a glitch on the line)."""
        super().inject_garbage(data)

    def new_parser(self) -> ft.PacketParser:
        return ft.PacketParser(status=False)

    def encode_status(self, status: Any) -> bytes:
        return ft.encode(status)

    async def receive(self, msg: ft.FeetechMessage | ft.CorruptPacket) -> None:
        if isinstance(msg, ft.CorruptPacket):
            self.corrupt_instructions += 1
            for servo in self.servos:
                if servo.id == msg.id:
                    servo.checksum_errors += 1
            return
        self.log_instruction(msg)
        if isinstance(msg, ft.SyncRead):
            order = [s for i in msg.ids for s in self.servos if s.id == i]
        else:
            order = sorted(self.servos, key=lambda s: s.id)
        await self.send_replies(order, lambda servo: servo.handle(msg))
