"""The RTC basic data types (OpenRTM's BasicDataType.idl and ExtendedDataTypes.idl) as
msgspec Structs.

Every type has ``tm`` (an :class:`RTCTime`, None until an OutPort stamps it with the
component's clock) and its payload, in the IDL's field order, so
``TimedDouble(RTCTime(0, 0), 1.5)`` reads like OpenRTM's ``RTC.TimedDouble(RTC.Time(0, 0),
1.5)``. Structs are plain values (frozen); msgspec encodes and validates them, which a
network transport uses. Types are found by their IDL name with :func:`resolve_data_type`.
"""

from __future__ import annotations

from typing import Annotated, Any

import msgspec

from ..errors import RTCBadParameterError

__all__ = [
    "DATA_TYPES",
    "Acceleration2D",
    "Acceleration3D",
    "Orientation3D",
    "Point2D",
    "Point3D",
    "Pose2D",
    "Pose3D",
    "RTCTime",
    "TimedAcceleration3D",
    "TimedBoolean",
    "TimedBooleanSeq",
    "TimedChar",
    "TimedCharSeq",
    "TimedDouble",
    "TimedDoubleSeq",
    "TimedFloat",
    "TimedFloatSeq",
    "TimedLong",
    "TimedLongSeq",
    "TimedOctet",
    "TimedOctetSeq",
    "TimedPoint2D",
    "TimedPoint3D",
    "TimedPose2D",
    "TimedPose3D",
    "TimedShort",
    "TimedShortSeq",
    "TimedState",
    "TimedString",
    "TimedStringSeq",
    "TimedULong",
    "TimedULongSeq",
    "TimedUShort",
    "TimedUShortSeq",
    "TimedValue",
    "TimedVelocity2D",
    "TimedWString",
    "Velocity2D",
    "Velocity3D",
    "data_type_name",
    "payload_type",
    "resolve_data_type",
    "stamp",
]

NS_PER_S = 1_000_000_000

Short = Annotated[int, msgspec.Meta(ge=-(2**15), le=2**15 - 1)]
UShort = Annotated[int, msgspec.Meta(ge=0, le=2**16 - 1)]
Long = Annotated[int, msgspec.Meta(ge=-(2**31), le=2**31 - 1)]
ULong = Annotated[int, msgspec.Meta(ge=0, le=2**32 - 1)]
Octet = Annotated[int, msgspec.Meta(ge=0, le=255)]
Char = Annotated[str, msgspec.Meta(min_length=1, max_length=1)]


class RTCTime(msgspec.Struct, frozen=True, array_like=True):
    """RTC::Time: seconds and nanoseconds."""

    sec: ULong = 0
    nsec: ULong = 0

    @classmethod
    def from_ns(cls, ns: int) -> RTCTime:
        sec, nsec = divmod(ns, NS_PER_S)
        return cls(sec, nsec)

    def to_ns(self) -> int:
        return self.sec * NS_PER_S + self.nsec


class TimedValue(msgspec.Struct, frozen=True, array_like=True):
    """Base of the Timed* types: ``tm`` then the payload fields."""

    tm: RTCTime | None = None


class TimedState(TimedValue, frozen=True):
    data: Short = 0


class TimedShort(TimedValue, frozen=True):
    data: Short = 0


class TimedLong(TimedValue, frozen=True):
    data: Long = 0


class TimedUShort(TimedValue, frozen=True):
    data: UShort = 0


class TimedULong(TimedValue, frozen=True):
    data: ULong = 0


class TimedFloat(TimedValue, frozen=True):
    data: float = 0.0


class TimedDouble(TimedValue, frozen=True):
    data: float = 0.0


class TimedChar(TimedValue, frozen=True):
    data: Char = "\0"


class TimedBoolean(TimedValue, frozen=True):
    data: bool = False


class TimedOctet(TimedValue, frozen=True):
    data: Octet = 0


class TimedString(TimedValue, frozen=True):
    data: str = ""


class TimedWString(TimedValue, frozen=True):
    data: str = ""


class TimedShortSeq(TimedValue, frozen=True):
    data: tuple[Short, ...] = ()


class TimedLongSeq(TimedValue, frozen=True):
    data: tuple[Long, ...] = ()


class TimedUShortSeq(TimedValue, frozen=True):
    data: tuple[UShort, ...] = ()


class TimedULongSeq(TimedValue, frozen=True):
    data: tuple[ULong, ...] = ()


class TimedFloatSeq(TimedValue, frozen=True):
    data: tuple[float, ...] = ()


class TimedDoubleSeq(TimedValue, frozen=True):
    data: tuple[float, ...] = ()


class TimedCharSeq(TimedValue, frozen=True):
    data: tuple[Char, ...] = ()


class TimedBooleanSeq(TimedValue, frozen=True):
    data: tuple[bool, ...] = ()


class TimedOctetSeq(TimedValue, frozen=True):
    data: bytes = b""


class TimedStringSeq(TimedValue, frozen=True):
    data: tuple[str, ...] = ()


# -- ExtendedDataTypes.idl (geometry) -----------------------------------------------------


class Point2D(msgspec.Struct, frozen=True, array_like=True):
    x: float = 0.0
    y: float = 0.0


class Pose2D(msgspec.Struct, frozen=True, array_like=True):
    position: Point2D = Point2D()
    heading: float = 0.0


class Velocity2D(msgspec.Struct, frozen=True, array_like=True):
    vx: float = 0.0
    vy: float = 0.0
    va: float = 0.0


class Acceleration2D(msgspec.Struct, frozen=True, array_like=True):
    ax: float = 0.0
    ay: float = 0.0


class Point3D(msgspec.Struct, frozen=True, array_like=True):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class Orientation3D(msgspec.Struct, frozen=True, array_like=True):
    r: float = 0.0
    p: float = 0.0
    y: float = 0.0


class Pose3D(msgspec.Struct, frozen=True, array_like=True):
    position: Point3D = Point3D()
    orientation: Orientation3D = Orientation3D()


class Velocity3D(msgspec.Struct, frozen=True, array_like=True):
    vx: float = 0.0
    vy: float = 0.0
    vz: float = 0.0
    vr: float = 0.0
    vp: float = 0.0
    va: float = 0.0


class Acceleration3D(msgspec.Struct, frozen=True, array_like=True):
    ax: float = 0.0
    ay: float = 0.0
    az: float = 0.0


class TimedPoint2D(TimedValue, frozen=True):
    data: Point2D = Point2D()


class TimedPose2D(TimedValue, frozen=True):
    data: Pose2D = Pose2D()


class TimedVelocity2D(TimedValue, frozen=True):
    data: Velocity2D = Velocity2D()


class TimedPoint3D(TimedValue, frozen=True):
    data: Point3D = Point3D()


class TimedPose3D(TimedValue, frozen=True):
    data: Pose3D = Pose3D()


class TimedAcceleration3D(TimedValue, frozen=True):
    data: Acceleration3D = Acceleration3D()


_ALL: tuple[type[TimedValue], ...] = (
    TimedState,
    TimedShort,
    TimedLong,
    TimedUShort,
    TimedULong,
    TimedFloat,
    TimedDouble,
    TimedChar,
    TimedBoolean,
    TimedOctet,
    TimedString,
    TimedWString,
    TimedShortSeq,
    TimedLongSeq,
    TimedUShortSeq,
    TimedULongSeq,
    TimedFloatSeq,
    TimedDoubleSeq,
    TimedCharSeq,
    TimedBooleanSeq,
    TimedOctetSeq,
    TimedStringSeq,
    TimedPoint2D,
    TimedPose2D,
    TimedVelocity2D,
    TimedPoint3D,
    TimedPose3D,
    TimedAcceleration3D,
)

DATA_TYPES: dict[str, type[TimedValue]] = {f"RTC::{t.__name__}": t for t in _ALL}
"""The types by IDL name (``RTC::TimedDouble``)."""


def data_type_name(data_type: type[TimedValue]) -> str:
    """``RTC::TimedDouble`` for TimedDouble."""
    return f"RTC::{data_type.__name__}"


def resolve_data_type(name: str) -> type[TimedValue]:
    """The type of an IDL name: ``RTC::TimedDouble``, ``TimedDouble``,
    ``IDL:RTC/TimedDouble:1.0`` or ``RTC/TimedDouble`` (BAD_PARAMETER otherwise)."""
    text = name.strip() if isinstance(name, str) else ""
    if text.startswith("IDL:"):
        text = text[4:].rsplit(":", 1)[0]
    text = text.replace("/", "::")
    if "::" not in text:
        text = f"RTC::{text}"
    found = DATA_TYPES.get(text)
    if found is None:
        raise RTCBadParameterError(
            "data type", name, "one of " + ", ".join(n.removeprefix("RTC::") for n in DATA_TYPES)
        )
    return found


def payload_type(data_type: type[TimedValue]) -> Any:
    """The annotated type of ``data_type.data``."""
    return msgspec.structs.fields(data_type)[1].type


def stamp(value: TimedValue, now_ns: int) -> TimedValue:
    """``value`` with ``tm`` set to ``now_ns`` when it has none."""
    if value.tm is not None:
        return value
    return msgspec.structs.replace(value, tm=RTCTime.from_ns(now_ns))
