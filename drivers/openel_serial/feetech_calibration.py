"""Calibration of Feetech STS servos (the SO-101's STS3215): the walk-through
``openel-async calibrate`` runs, and the calibration file it writes.

The walk-through (:func:`calibrate_servos`), as LeRobot's ``lerobot-calibrate`` does it:

1. every servo is pinged, then its torque turned off (the arm is moved by hand);
2. the user puts the arm in the middle of its range and confirms (``ask("middle", ...)``);
   each servo's Homing Offset (31) is computed so that this pose reads step 2048 (0 rad)
   and written to its EEPROM behind the lock (:meth:`FeetechPort.write_eeprom`):
   Present Position = the encoder's position - Homing Offset, so the new offset is
   ``old offset + present - 2048``, brought into -2047..2047 (sign-magnitude, bit 11);
3. the user moves each joint through its full range by hand and confirms
   (``ask("range", ...)``) while the present positions are streamed -- one SYNC READ of
   Present Position (56) of every servo per cycle -- and the minimum and maximum of each are
   kept (``show`` is called after each cycle with every joint's :class:`JointReading`);
4. the minima and maxima are written as Min/Max Angle Limit (9, 11), EEPROM behind the lock;
   a joint that did not move is refused (:class:`CalibrationError`) before anything of
   step 4 is written.

The calibration file (YAML; JSON is YAML too), strict -- an unknown key, a missing one or a
value out of range is refused with ``FILE:LINE:COLUMN`` (:func:`load_calibration`)::

    version: 1
    joints:
      shoulder_pan: {id: 1, homing_offset: -112, range_min: 780, range_max: 3310, drive_mode: 0}

per joint (the component's name in the rig): its servo ``id``, ``homing_offset`` (the Homing
Offset (31) written, steps), ``range_min`` / ``range_max`` (the Min/Max Angle Limits (9, 11),
steps, in the frame the offset gives) and ``drive_mode`` (0: the servo's direction; 1: the
component reverses it -- the STS has no such register; calibrate writes 0, edit it to turn a
joint the other way). A serial bus with ``calibration: FILE`` hands each servo its entry
(:class:`~openel_serial.feetech_servo.FeetechServo` ``calibration``).
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Final, Literal

import anyio
import msgspec
import yaml

from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_async.positioned import SAFE_DUMPER, DocumentError, convert, load_yaml
from openel_serial import feetech as ft
from openel_serial.feetech_port import FeetechPort

__all__ = [
    "CALIBRATION_VERSION",
    "CalibrationError",
    "CalibrationFile",
    "JointCalibration",
    "JointReading",
    "calibrate_servos",
    "dump_calibration",
    "homing_offset_for",
    "load_calibration",
    "write_calibration",
]

log = get_logger(__name__)

S = ft.STS
CALIBRATION_VERSION: Final = 1
MAX_OFFSET: Final = (1 << 11) - 1
"""The largest Homing Offset (31) magnitude: sign-magnitude with the sign in bit 11."""

Ask = Callable[[str, str], Awaitable[None]]
"""``ask(step, prompt)``: returns when the user confirms ``step`` (``middle``, ``range``)."""


class CalibrationError(HALError):
    """The walk-through cannot go on (a joint that did not move, a servo that is missing)."""


class JointCalibration(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """One joint's entry of the calibration file (see the module docstring)."""

    id: Annotated[int, msgspec.Meta(ge=0, le=ft.MAX_ID)]
    homing_offset: Annotated[int, msgspec.Meta(ge=-MAX_OFFSET, le=MAX_OFFSET)]
    range_min: Annotated[int, msgspec.Meta(ge=0, le=ft.TICKS_PER_REV - 1)]
    range_max: Annotated[int, msgspec.Meta(ge=0, le=ft.TICKS_PER_REV - 1)]
    drive_mode: Literal[0, 1] = 0

    def radians(self) -> tuple[float, float]:
        """The range in the component's radians (drive mode applied), low < high."""
        sign = -1 if self.drive_mode else 1
        a = sign * ft.ticks_to_rad(self.range_min)
        b = sign * ft.ticks_to_rad(self.range_max)
        return (min(a, b), max(a, b))


class CalibrationFile(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """The whole file: ``version`` 1 and the ``joints`` by component name."""

    joints: dict[str, JointCalibration]
    version: Literal[1] = CALIBRATION_VERSION


def load_calibration(path: str | Path) -> CalibrationFile:
    """Read a calibration file; :class:`~openel_async.positioned.DocumentError`
    (``FILE:LINE:COLUMN: ...``) for anything it refuses, OSError when it cannot be read."""
    source = str(path)
    text = Path(path).read_text(encoding="utf-8")
    doc = load_yaml(text, source)
    if not isinstance(doc.data, Mapping):
        raise DocumentError(
            "a calibration file is a mapping with 'version' and 'joints'",
            location=doc.where(doc.data),
        )
    # each joint converted on its own: a refusal inside one is located at its key
    top = convert(doc, doc.data, _RawFile, "calibration")
    joints: dict[str, JointCalibration] = {}
    for name, raw in doc.data["joints"].items():  # the parsed objects: their positions
        where = f"calibration.joints.{name}"
        entry = convert(doc, raw, JointCalibration, where)
        if entry.range_min >= entry.range_max:
            raise DocumentError(
                f"{where}: range_max ({entry.range_max}) must be above range_min "
                f"({entry.range_min})",
                path=f"{where}.range_max",
                location=doc.value(raw, "range_max"),
            )
        joints[name] = entry
    return CalibrationFile(joints=joints, version=top.version)


class _RawFile(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    joints: dict[str, dict[str, Any]]
    version: Literal[1] = CALIBRATION_VERSION


def dump_calibration(calibration: CalibrationFile, *, comment: str = "") -> str:
    """The file's text: a comment, then one flow mapping per joint (as the module shows)."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append(f"version: {calibration.version}")
    lines.append("joints:")
    for name, entry in calibration.joints.items():
        fields = msgspec.structs.asdict(entry)
        inner = ", ".join(f"{k}: {v}" for k, v in fields.items())
        key = yaml.dump(name, Dumper=SAFE_DUMPER).removesuffix("\n...\n").strip()
        lines.append(f"  {key}: {{{inner}}}")
    return "\n".join(lines) + "\n"


def write_calibration(path: str | Path, calibration: CalibrationFile, *, comment: str = "") -> None:
    """Write the file (through a temporary file and a rename: never half written)."""
    target = Path(path)
    partial = target.with_name(f".{target.name}.partial")
    partial.write_text(dump_calibration(calibration, comment=comment), encoding="utf-8")
    partial.replace(target)


def homing_offset_for(old_offset: int, present: int) -> int:
    """The Homing Offset (31) that makes a servo reading ``present`` with ``old_offset`` read
    step 2048: ``old + present - 2048`` modulo a turn, in -2047..2047 (the register cannot hold
    -2048: that pose then reads 2047)."""
    offset = (old_offset + present) % ft.TICKS_PER_REV - ft.CENTER_TICK
    return max(-MAX_OFFSET, offset)


@dataclass(slots=True)
class JointReading:
    """One joint during the walk-through: its latest present position and the range seen."""

    name: str
    id: int
    position: int
    low: int
    high: int

    @property
    def span_rad(self) -> float:
        return (self.high - self.low) * 2 * math.pi / ft.TICKS_PER_REV


async def _torque_off(port: FeetechPort, ids: list[int]) -> None:
    await port.sync_write_item(S.TORQUE_ENABLE, dict.fromkeys(ids, 0))
    for servo_id in ids:  # read back: a SYNC WRITE has no status
        if await port.read_item(servo_id, S.TORQUE_ENABLE):
            raise CalibrationError(f"servo {servo_id}: the torque stays on")


async def calibrate_servos(
    port: FeetechPort,
    joints: Mapping[str, int],
    ask: Ask,
    *,
    show: Callable[[list[JointReading]], None] | None = None,
    period: float = 0.02,
) -> dict[str, JointCalibration]:
    """Run the walk-through (module docstring) on ``port`` for ``joints`` ({name: servo id});
    the entries of the calibration file, by name. ``period``: seconds between the streamed
    SYNC READs (0: back to back). The port must be entered; no component may be using it."""
    if not joints:
        raise BadParameterError("joints", joints, "at least one {name: servo id}")
    if len(set(joints.values())) != len(joints):
        raise BadParameterError("joints", dict(joints), "distinct servo ids")
    ids = list(joints.values())
    for name, servo_id in joints.items():
        try:
            await port.ping(servo_id)
        except TimeoutError:
            raise CalibrationError(
                f"{name}: servo {servo_id} does not answer on {port.url}"
            ) from None
    await _torque_off(port, ids)
    log.info("feetech_calibration_torque_off", ids=ids)

    # -- the middle: homing offsets ---------------------------------------------------------
    await ask("middle", "Move the arm to the middle of its range, then press Enter")
    present = await _positions(port, ids)
    offsets: dict[int, int] = {}
    for servo_id in ids:
        old = await port.read_item(servo_id, S.HOMING_OFFSET)
        offsets[servo_id] = homing_offset_for(old, present[servo_id])
        await port.write_eeprom(servo_id, [(S.HOMING_OFFSET, offsets[servo_id])])
    log.info("feetech_calibration_homing_offsets", offsets=offsets)

    # -- the ranges, streamed ----------------------------------------------------------------
    present = await _positions(port, ids)
    readings = [JointReading(n, i, present[i], present[i], present[i]) for n, i in joints.items()]
    done = anyio.Event()
    failed: list[Exception] = []

    async def confirm() -> None:
        try:
            await ask("range", "Move each joint through its full range by hand, then press Enter")
        except Exception as exc:  # raised below, outside the task group
            failed.append(exc)
        finally:
            done.set()

    async with anyio.create_task_group() as tg:
        tg.start_soon(confirm)
        while not done.is_set():
            present = await _positions(port, ids)
            for reading in readings:
                value = present[reading.id]
                reading.position = value
                reading.low = min(reading.low, value)
                reading.high = max(reading.high, value)
            if show is not None:
                show(readings)
            with anyio.move_on_after(period):
                await done.wait()
    if failed:
        raise failed[0]
    still = [r.name for r in readings if r.high - r.low < 2]
    if still:
        raise CalibrationError(
            f"{', '.join(still)} did not move: move each joint through its range (nothing "
            "written for the ranges; the homing offsets are written)"
        )
    result: dict[str, JointCalibration] = {}
    for reading in readings:
        await port.write_eeprom(
            reading.id, [(S.MIN_ANGLE_LIMIT, reading.low), (S.MAX_ANGLE_LIMIT, reading.high)]
        )
        result[reading.name] = JointCalibration(
            id=reading.id,
            homing_offset=offsets[reading.id],
            range_min=reading.low,
            range_max=reading.high,
        )
    log.info("feetech_calibration_ranges", ranges={r.name: (r.low, r.high) for r in readings})
    return result


async def _positions(port: FeetechPort, ids: list[int]) -> dict[int, int]:
    """One SYNC READ of Present Position (56) of every servo."""
    item = S.PRESENT_POSITION
    data = await port.sync_read(ids, item.address, item.size)
    return {i: item.decode(d) for i, d in data.items()}
