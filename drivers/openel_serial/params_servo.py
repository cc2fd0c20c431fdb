"""Serial servos' control tables for ``openel-async param``: a Dynamixel X series servo's
(protocol 2.0; XM430-W350, XL430-W250 -- without the current items) and a Feetech
STS/SMS servo's (STS3215), item by item: address, size, access, unit, and the area --
EEPROM (kept at power-off) or RAM.

Names are the e-manuals' (``Profile Velocity``, ``Torque Limit``), matched ignoring case,
with ``_`` or ``-`` for spaces (``torque_limit``); an item is also named by its address
(``112``). Values are the servo's own numbers; their unit is shown scaled (Profile
Velocity 100 = 22.9 rpm; a position of 2048 steps = 180°).

Writes: a Dynamixel's EEPROM items (addresses 0..63) are writable only with the torque off
(:meth:`ServoParameters.write_blocker` says so when Torque Enable reads 1; the write turns
the torque off first only when asked to, and leaves it off). A Feetech's EEPROM items
(0..39) go through :meth:`~openel_serial.feetech_port.FeetechPort.write_eeprom` (Lock = 0,
the write, Lock = 1, read back), so that they are kept at power-off. Torque Enable, the
goals and Feetech's Lock are commands: read, never written here (``openel-async param``
never enables or moves a servo).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from openel_async.errors import BadParameterError
from openel_async.params import ParameterInfo, ParamValue, Storage, not_found

from . import dynamixel as dx
from . import feetech as ft
from .feetech_port import FeetechPort
from .port import DynamixelPort

__all__ = ["DYNAMIXEL_X", "STS", "Item", "ServoParameters"]

_DEG_X: Final = 360 / 4096  # 0.088° per pulse
_DEG_STS: Final = 360 / 4096  # STS3215: 4096 steps per turn


@dataclass(frozen=True)
class Item:
    """One control-table item."""

    address: int
    size: int
    name: str
    access: str = "rw"
    unit: str = ""
    scale: float = 1.0
    signed: bool = False
    """Dynamixel: two's complement."""
    sign_bit: int | None = None
    """Feetech: sign-magnitude with the sign in this bit."""
    command: bool = False
    current: bool = False
    """A current item (absent from the XL430)."""


_X_EEPROM_END: Final = 64
DYNAMIXEL_X: Final = (
    Item(0, 2, "Model Number", "ro"),
    Item(2, 4, "Model Information", "ro"),
    Item(6, 1, "Firmware Version", "ro"),
    Item(7, 1, "ID"),
    Item(8, 1, "Baud Rate"),
    Item(9, 1, "Return Delay Time", unit="µs", scale=2.0),
    Item(10, 1, "Drive Mode"),
    Item(11, 1, "Operating Mode"),
    Item(12, 1, "Secondary ID"),
    Item(13, 1, "Protocol Type"),
    Item(20, 4, "Homing Offset", unit="°", scale=_DEG_X, signed=True),
    Item(24, 4, "Moving Threshold", unit="rpm", scale=dx.VELOCITY_UNIT_RPM),
    Item(31, 1, "Temperature Limit", unit="°C"),
    Item(32, 2, "Max Voltage Limit", unit="V", scale=dx.VOLTAGE_UNIT_V),
    Item(34, 2, "Min Voltage Limit", unit="V", scale=dx.VOLTAGE_UNIT_V),
    Item(36, 2, "PWM Limit", unit="%", scale=100 / dx.PWM_FULL_SCALE),
    Item(38, 2, "Current Limit", unit="mA", scale=dx.CURRENT_UNIT_A * 1000, current=True),
    Item(44, 4, "Velocity Limit", unit="rpm", scale=dx.VELOCITY_UNIT_RPM),
    Item(48, 4, "Max Position Limit", unit="°", scale=_DEG_X),
    Item(52, 4, "Min Position Limit", unit="°", scale=_DEG_X),
    Item(63, 1, "Shutdown"),
    Item(64, 1, "Torque Enable", command=True),
    Item(65, 1, "LED"),
    Item(68, 1, "Status Return Level"),
    Item(69, 1, "Registered Instruction", "ro"),
    Item(70, 1, "Hardware Error Status", "ro"),
    Item(76, 2, "Velocity I Gain"),
    Item(78, 2, "Velocity P Gain"),
    Item(80, 2, "Position D Gain"),
    Item(82, 2, "Position I Gain"),
    Item(84, 2, "Position P Gain"),
    Item(88, 2, "Feedforward 2nd Gain"),
    Item(90, 2, "Feedforward 1st Gain"),
    Item(98, 1, "Bus Watchdog", unit="ms", scale=dx.BUS_WATCHDOG_UNIT_S * 1000, signed=True),
    Item(100, 2, "Goal PWM", unit="%", scale=100 / dx.PWM_FULL_SCALE, signed=True, command=True),
    Item(102, 2, "Goal Current", unit="mA", scale=2.69, signed=True, command=True, current=True),
    Item(
        104, 4, "Goal Velocity", unit="rpm", scale=dx.VELOCITY_UNIT_RPM, signed=True, command=True
    ),
    Item(108, 4, "Profile Acceleration", unit="rev/min²", scale=dx.ACCELERATION_UNIT_RPM2),
    Item(112, 4, "Profile Velocity", unit="rpm", scale=dx.VELOCITY_UNIT_RPM),
    Item(116, 4, "Goal Position", unit="°", scale=_DEG_X, signed=True, command=True),
    Item(120, 2, "Realtime Tick", "ro", unit="ms"),
    Item(122, 1, "Moving", "ro"),
    Item(123, 1, "Moving Status", "ro"),
    Item(124, 2, "Present PWM", "ro", unit="%", scale=100 / dx.PWM_FULL_SCALE, signed=True),
    Item(126, 2, "Present Current", "ro", unit="mA", scale=2.69, signed=True, current=True),
    Item(128, 4, "Present Velocity", "ro", unit="rpm", scale=dx.VELOCITY_UNIT_RPM, signed=True),
    Item(132, 4, "Present Position", "ro", unit="°", scale=_DEG_X, signed=True),
    Item(136, 4, "Velocity Trajectory", "ro", unit="rpm", scale=dx.VELOCITY_UNIT_RPM, signed=True),
    Item(140, 4, "Position Trajectory", "ro", unit="°", scale=_DEG_X, signed=True),
    Item(144, 2, "Present Input Voltage", "ro", unit="V", scale=dx.VOLTAGE_UNIT_V),
    Item(146, 1, "Present Temperature", "ro", unit="°C"),
)
"""The X series' control table (protocol 2.0 e-manual of the XM430-W350: EEPROM 0..63, RAM
64..147; units as there)."""

_STS_EEPROM_END: Final = 40
STS: Final = (
    Item(0, 1, "Firmware Major", "ro"),
    Item(1, 1, "Firmware Minor", "ro"),
    Item(3, 2, "Model Number", "ro"),
    Item(5, 1, "ID"),
    Item(6, 1, "Baud Rate"),
    Item(7, 1, "Return Delay", unit="µs", scale=ft.RETURN_DELAY_UNIT_S * 1e6),
    Item(8, 1, "Response Status Level"),
    Item(9, 2, "Min Angle Limit", unit="°", scale=_DEG_STS),
    Item(11, 2, "Max Angle Limit", unit="°", scale=_DEG_STS),
    Item(13, 1, "Max Temperature Limit", unit="°C"),
    Item(14, 1, "Max Voltage Limit", unit="V", scale=ft.VOLTAGE_UNIT_V),
    Item(15, 1, "Min Voltage Limit", unit="V", scale=ft.VOLTAGE_UNIT_V),
    Item(16, 2, "Max Torque Limit", unit="%", scale=0.1),
    Item(18, 1, "Phase"),
    Item(19, 1, "Unloading Condition"),
    Item(20, 1, "LED Alarm Condition"),
    Item(21, 1, "P Coefficient"),
    Item(22, 1, "D Coefficient"),
    Item(23, 1, "I Coefficient"),
    Item(24, 2, "Minimum Startup Force", unit="%", scale=0.1),
    Item(26, 1, "CW Dead Zone", unit="°", scale=_DEG_STS),
    Item(27, 1, "CCW Dead Zone", unit="°", scale=_DEG_STS),
    Item(28, 2, "Protection Current", unit="mA", scale=ft.CURRENT_UNIT_A * 1000),
    Item(30, 1, "Angular Resolution"),
    Item(31, 2, "Homing Offset", unit="°", scale=_DEG_STS, sign_bit=11),
    Item(33, 1, "Operating Mode"),
    Item(34, 1, "Protective Torque", unit="%"),
    Item(35, 1, "Protection Time", unit="ms", scale=10.0),
    Item(36, 1, "Overload Torque", unit="%"),
    Item(40, 1, "Torque Enable", command=True),
    Item(41, 1, "Acceleration", unit="steps/s²", scale=ft.ACCELERATION_UNIT_STEPS_S2),
    Item(42, 2, "Goal Position", unit="°", scale=_DEG_STS, sign_bit=15, command=True),
    Item(44, 2, "Goal Time", unit="ms", command=True),
    Item(46, 2, "Goal Speed", unit="steps/s", sign_bit=15, command=True),
    Item(48, 2, "Torque Limit", unit="%", scale=0.1),
    Item(55, 1, "Lock", command=True),
    Item(56, 2, "Present Position", "ro", unit="°", scale=_DEG_STS, sign_bit=15),
    Item(58, 2, "Present Speed", "ro", unit="steps/s", sign_bit=15),
    Item(60, 2, "Present Load", "ro", unit="%", scale=0.1, sign_bit=10),
    Item(62, 1, "Present Voltage", "ro", unit="V", scale=ft.VOLTAGE_UNIT_V),
    Item(63, 1, "Present Temperature", "ro", unit="°C"),
    Item(64, 1, "Async Write Flag", "ro"),
    Item(65, 1, "Servo Status", "ro"),
    Item(66, 1, "Moving", "ro"),
    Item(69, 2, "Present Current", "ro", unit="mA", scale=ft.CURRENT_UNIT_A * 1000, sign_bit=15),
)
"""The STS/SMS series' control table (STS3215; :class:`openel_serial.feetech.STS`'s
addresses, Feetech's memory table names and units: EEPROM 0..39, SRAM 40..)."""


def _fold(text: str) -> str:
    return " ".join(text.replace("_", " ").replace("-", " ").split()).casefold()


def _range(item: Item) -> tuple[int, int]:
    bits = item.size * 8
    if item.signed:
        return -(2 ** (bits - 1)), 2 ** (bits - 1) - 1
    if item.sign_bit is not None:
        magnitude = 2**item.sign_bit - 1
        return -magnitude, magnitude
    return 0, 2**bits - 1


class ServoParameters:
    """One servo's control table on its port (see the module docstring)."""

    def __init__(
        self,
        port: DynamixelPort | FeetechPort,
        servo_id: int,
        table: Sequence[Item],
        *,
        model: str,
    ) -> None:
        self.port = port
        self.servo_id = servo_id
        self.model = model
        self.feetech = isinstance(port, FeetechPort)
        self._eeprom_end = _STS_EEPROM_END if self.feetech else _X_EEPROM_END
        self._items = tuple(table)
        self._infos = tuple(self._info(i) for i in self._items)
        self._by_name = {_fold(i.name): n for n, i in enumerate(self._items)}
        self._by_address = {i.address: n for n, i in enumerate(self._items)}

    @classmethod
    def dynamixel(
        cls, port: DynamixelPort, dxl_id: int, *, current: bool = True
    ) -> ServoParameters:
        table = [i for i in DYNAMIXEL_X if current or not i.current]
        return cls(port, dxl_id, table, model="Dynamixel X series (protocol 2.0)")

    @classmethod
    def sts(cls, port: FeetechPort, servo_id: int) -> ServoParameters:
        return cls(port, servo_id, STS, model="Feetech STS (STS3215)")

    def _info(self, item: Item) -> ParameterInfo:
        low, high = _range(item)
        eeprom = item.address < self._eeprom_end
        storage: Storage = "eeprom" if eeprom else ("ram" if item.access == "rw" else "volatile")
        kind = "int8" if item.size == 1 else "int16" if item.size == 2 else "int32"
        kind = kind if (item.signed or item.sign_bit is not None) else "u" + kind
        description = (
            "a command (enables or moves the servo): read-only here" if item.command else ""
        )
        if eeprom and not self.feetech and item.access == "rw":
            description = "EEPROM: writable only with the torque off"
        return ParameterInfo(
            name=item.name,
            address=f"{item.address} ({item.size} byte{'s' if item.size > 1 else ''})",
            type=kind,
            access="rw" if item.access == "rw" else "ro",
            unit=item.unit,
            storage=storage,
            description=description,
            low=low,
            high=high,
            scale=item.scale,
            command=item.command,
        )

    @property
    def source(self) -> str:
        return f"{self.model} servo {self.servo_id}, control table ({len(self._items)} items)"

    def parameters(self) -> Sequence[ParameterInfo]:
        return self._infos

    def parameter(self, key: str) -> ParameterInfo:
        text = key.strip()
        index = self._by_name.get(_fold(text))
        if index is None and text.isdigit():
            index = self._by_address.get(int(text))
        if index is None:
            raise not_found(key, [i.name for i in self._items], self.model)
        return self._infos[index]

    def _item(self, info: ParameterInfo) -> Item:
        return self._items[self._by_name[_fold(info.name)]]

    def _codec(self, item: Item) -> dx.ControlItem | ft.ControlItem:
        if self.feetech:
            return ft.ControlItem(item.address, item.size, item.sign_bit)
        return dx.ControlItem(item.address, item.size, item.signed)

    async def _read_item(self, item: Item) -> int:
        codec = self._codec(item)
        if isinstance(self.port, DynamixelPort):
            data = await self.port.read(self.servo_id, item.address, item.size, check_alert=False)
        else:
            data = await self.port.read(self.servo_id, item.address, item.size)
        return codec.decode(bytes(data))

    async def read(self, info: ParameterInfo) -> ParamValue:
        return await self._read_item(self._item(info))

    async def write_blocker(self, info: ParameterInfo) -> str | None:
        item = self._item(info)
        if self.feetech or item.address >= self._eeprom_end:
            return None
        torque = await self._read_item(self._item(self.parameter("Torque Enable")))
        if torque:
            return (
                f"the torque of servo {self.servo_id} is on (Torque Enable = 1): the X series "
                "takes EEPROM writes only with the torque off"
            )
        return None

    async def write(self, info: ParameterInfo, value: ParamValue, *, unblock: bool = False) -> None:
        item = self._item(info)
        if item.command or item.access != "rw":
            raise BadParameterError(info.name, value, "a writable setting (not a command)")
        if not isinstance(value, int) or isinstance(value, bool):
            raise BadParameterError(info.name, value, "an integer")
        codec = self._codec(item)
        try:
            data = codec.encode(value)
        except ValueError as exc:
            raise BadParameterError(info.name, value, str(exc)) from None
        port = self.port
        if isinstance(port, FeetechPort):
            if item.address < self._eeprom_end:
                assert isinstance(codec, ft.ControlItem)
                await port.write_eeprom(self.servo_id, [(codec, value)])
            else:
                await port.write(self.servo_id, item.address, data)
            return
        blocker = await self.write_blocker(info)
        if blocker is not None:
            if not unblock:
                raise BadParameterError(
                    info.name, value, f"a write with the torque off ({blocker})"
                )
            await port.write(self.servo_id, 64, bytes((0,)), check_alert=False)
        await port.write(self.servo_id, item.address, data, check_alert=False)
