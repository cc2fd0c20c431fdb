"""NMEA 0183 sentences (GGA, RMC, GSA, GSV, GST) with checksum, pure and byte-exact.

Sentence: ``$`` + address (talker + type, e.g. ``GNGGA``) + ``,``-separated
fields + ``*hh`` (XOR of every character between ``$`` and ``*``, two hex
digits) + CRLF. Any talker id is accepted; ``$P...`` sentences are proprietary.
Sentences of other types (and proprietary ``$P...`` ones such as MediaTek's
``$PMTK``) decode to :class:`RawSentence`.

Conventions: latitude/longitude are signed decimal degrees (N/E positive);
RMC speed is m/s (knots on the wire), course stays in degrees with
:attr:`RMC.course_rad` alongside; magnetic variation is signed degrees (E
positive); two-digit years map to 1980..2079; empty fields are ``None``.

:func:`decode_sentence` raises only :class:`~openel_serial.errors.NmeaDecodeError`
(checksum mismatches as :class:`~openel_serial.errors.NmeaChecksumError`);
:class:`NmeaParser` never raises on garbage.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, TypeAlias

from openel_serial.errors import NmeaChecksumError, NmeaDecodeError

__all__ = [
    "GGA",
    "GSA",
    "GST",
    "GSV",
    "KNOT_M_S",
    "MAX_SENTENCE_LENGTH",
    "RMC",
    "FixQuality",
    "NmeaChecksumError",
    "NmeaDecodeError",
    "NmeaParser",
    "RawSentence",
    "SatelliteInView",
    "Sentence",
    "checksum",
    "decode_sentence",
    "format_gga",
    "format_gsa",
    "format_gst",
    "format_gsv",
    "format_rmc",
    "format_sentence",
]

KNOT_M_S: Final = 1852.0 / 3600.0
#: NMEA 0183 limit including ``$`` and CRLF; the parser tolerates longer lines.
MAX_SENTENCE_LENGTH: Final = 82

_TALKER_RE: Final = re.compile(r"[A-Z][A-Z0-9]")
_ADDRESS_RE: Final = re.compile(r"([A-Z][A-Z0-9])([A-Z]{3})|P([A-Z0-9]{1,8})")
_TIME_RE: Final = re.compile(r"([0-9]{2})([0-9]{2})([0-9]{2})(?:\.([0-9]{1,9}))?")
_DATE_RE: Final = re.compile(r"([0-9]{2})([0-9]{2})([0-9]{2})")
_LAT_RE: Final = re.compile(r"([0-9]{2})([0-9]{2}(?:\.[0-9]{1,9})?)")
_LON_RE: Final = re.compile(r"([0-9]{3})([0-9]{2}(?:\.[0-9]{1,9})?)")
_FLOAT_RE: Final = re.compile(r"[+-]?(?:[0-9]{1,12}(?:\.[0-9]{0,12})?|\.[0-9]{1,12})")
_INT_RE: Final = re.compile(r"[0-9]{1,4}")
_HEX2_RE: Final = re.compile(r"[0-9A-Fa-f]{2}")
_HEX1_RE: Final = re.compile(r"[0-9A-F]")
_DELIMITER_RE: Final = re.compile(rb"[$\n]")
_DOLLAR: Final = ord("$")


class FixQuality(IntEnum):
    """GGA field 6 (kept as a plain int in :class:`GGA`)."""

    INVALID = 0
    GPS = 1
    DGPS = 2
    PPS = 3
    RTK_FIXED = 4
    RTK_FLOAT = 5
    ESTIMATED = 6
    MANUAL = 7
    SIMULATION = 8


def _check_talker(talker: str) -> None:
    if not _TALKER_RE.fullmatch(talker):
        raise ValueError(f"talker id {talker!r} is not two upper-case characters")


def _check_latlon(latitude: float | None, longitude: float | None) -> None:
    if latitude is not None and not -90.0 <= latitude <= 90.0:
        raise ValueError(f"latitude {latitude} outside -90..90")
    if longitude is not None and not -180.0 <= longitude <= 180.0:
        raise ValueError(f"longitude {longitude} outside -180..180")


@dataclass(frozen=True)
class GGA:
    """Global positioning system fix data."""

    talker: str = "GP"
    time: dt.time | None = None  # UTC
    latitude: float | None = None  # deg, N positive
    longitude: float | None = None  # deg, E positive
    fix_quality: int = FixQuality.INVALID
    satellites: int | None = None
    hdop: float | None = None
    altitude: float | None = None  # m above mean sea level
    geoid_separation: float | None = None  # m, geoid above WGS84 ellipsoid
    dgps_age: float | None = None  # s
    dgps_station: int | None = None

    def __post_init__(self) -> None:
        _check_talker(self.talker)
        _check_latlon(self.latitude, self.longitude)
        if not 0 <= self.fix_quality <= 9:
            raise ValueError(f"fix quality {self.fix_quality} outside 0..9")
        if self.satellites is not None and not 0 <= self.satellites <= 999:
            raise ValueError(f"satellites {self.satellites} outside 0..999")
        if self.dgps_station is not None and not 0 <= self.dgps_station <= 9999:
            raise ValueError(f"DGPS station {self.dgps_station} outside 0..9999")


@dataclass(frozen=True)
class RMC:
    """Recommended minimum specific GNSS data."""

    talker: str = "GP"
    time: dt.time | None = None  # UTC
    valid: bool = False  # status A (True) / V (False)
    latitude: float | None = None
    longitude: float | None = None
    speed: float | None = None  # m/s over ground
    course: float | None = None  # deg true
    date: dt.date | None = None
    magnetic_variation: float | None = None  # deg, E positive
    mode: str | None = None  # NMEA 2.3+ FAA mode indicator (A, D, E, N, ...)

    def __post_init__(self) -> None:
        _check_talker(self.talker)
        _check_latlon(self.latitude, self.longitude)
        if self.mode is not None and not re.fullmatch(r"[A-Z]", self.mode):
            raise ValueError(f"mode indicator {self.mode!r} is not one upper-case letter")

    @property
    def course_rad(self) -> float | None:
        return None if self.course is None else math.radians(self.course)


@dataclass(frozen=True)
class GSA:
    """GNSS DOP and active satellites (NMEA 4.1+ adds the GNSS system id)."""

    talker: str = "GP"
    selection: str = "A"  # A automatic / M manual 2D-3D
    fix_type: int = 1  # 1 no fix, 2 2D, 3 3D
    satellites: tuple[int, ...] = ()  # ids used in the fix (up to 12)
    pdop: float | None = None
    hdop: float | None = None
    vdop: float | None = None
    system_id: int | None = None  # NMEA 4.1: 1 GPS, 2 GLONASS, 3 Galileo, 4 BeiDou, ...

    def __post_init__(self) -> None:
        _check_talker(self.talker)
        if len(self.satellites) > 12:
            raise ValueError(f"{len(self.satellites)} satellites: GSA lists at most 12")


@dataclass(frozen=True)
class SatelliteInView:
    """One satellite of a GSV sentence; ``snr`` is C/N0 in dB-Hz, None when not tracked."""

    prn: int
    elevation: int | None = None  # deg
    azimuth: int | None = None  # deg true
    snr: int | None = None  # dB-Hz


@dataclass(frozen=True)
class GSV:
    """GNSS satellites in view: message ``number`` of ``count`` of one talker's cycle."""

    talker: str = "GP"
    count: int = 1
    number: int = 1
    in_view: int = 0
    satellites: tuple[SatelliteInView, ...] = ()  # up to 4 per sentence
    signal_id: str | None = None  # NMEA 4.1 signal id (one hex digit)

    def __post_init__(self) -> None:
        _check_talker(self.talker)
        if not 1 <= self.number <= self.count <= 9:
            raise ValueError(f"GSV message {self.number} of {self.count}")
        if len(self.satellites) > 4:
            raise ValueError(f"{len(self.satellites)} satellites: GSV has at most 4")


@dataclass(frozen=True)
class GST:
    """GNSS pseudorange error statistics (standard deviations in metres)."""

    talker: str = "GP"
    time: dt.time | None = None  # UTC of the associated fix
    rms: float | None = None  # RMS of the range residuals
    major: float | None = None  # sigma of the error ellipse's semi-major axis
    minor: float | None = None
    orientation: float | None = None  # deg true of the semi-major axis
    latitude_sigma: float | None = None
    longitude_sigma: float | None = None
    altitude_sigma: float | None = None

    def __post_init__(self) -> None:
        _check_talker(self.talker)


@dataclass(frozen=True)
class RawSentence:
    """A valid sentence of another type; ``talker`` is ``"P"`` for proprietary ones."""

    talker: str
    sentence_type: str
    fields: tuple[str, ...]


Sentence: TypeAlias = GGA | RMC | GSA | GSV | GST | RawSentence


# --- Checksum and framing ------------------------------------------------------------------


def checksum(body: str) -> int:
    """XOR of the characters between ``$`` and ``*``."""
    value = 0
    for byte in body.encode("ascii"):
        value ^= byte
    return value


def format_sentence(address: str, fields: Sequence[str]) -> str:
    """``$address,fields*hh`` + CRLF."""
    body = ",".join((address, *fields))
    if not body.isascii() or any(c in body for c in "$*\r\n!"):
        raise ValueError(f"reserved or non-ASCII character in {body!r}")
    return f"${body}*{checksum(body):02X}\r\n"


# --- Field codecs --------------------------------------------------------------------------


def _float(text: str) -> float | None:
    if not text:
        return None
    if not _FLOAT_RE.fullmatch(text):
        raise NmeaDecodeError(f"bad number {text!r}")
    return float(text)


def _int(text: str) -> int | None:
    if not text:
        return None
    if not _INT_RE.fullmatch(text):
        raise NmeaDecodeError(f"bad integer {text!r}")
    return int(text)


def _time(text: str) -> dt.time | None:
    if not text:
        return None
    match = _TIME_RE.fullmatch(text)
    if not match:
        raise NmeaDecodeError(f"bad time {text!r}")
    hh, mm, ss, frac = match.groups()
    micro = int((frac or "").ljust(6, "0")[:6])  # truncate below 1 us
    try:
        return dt.time(int(hh), int(mm), int(ss), micro)
    except ValueError as exc:
        raise NmeaDecodeError(f"bad time {text!r}: {exc}") from None


def _date(text: str) -> dt.date | None:
    if not text:
        return None
    match = _DATE_RE.fullmatch(text)
    if not match:
        raise NmeaDecodeError(f"bad date {text!r}")
    day, month, yy = (int(g) for g in match.groups())
    year = 2000 + yy if yy < 80 else 1900 + yy
    try:
        return dt.date(year, month, day)
    except ValueError as exc:
        raise NmeaDecodeError(f"bad date {text!r}: {exc}") from None


def _angle(value: str, hemisphere: str, *, latitude: bool) -> float | None:
    if not value and not hemisphere:
        return None
    positive, negative = ("N", "S") if latitude else ("E", "W")
    pattern = _LAT_RE if latitude else _LON_RE
    match = pattern.fullmatch(value)
    if not match or hemisphere not in (positive, negative):
        raise NmeaDecodeError(f"bad {'latitude' if latitude else 'longitude'} {value},{hemisphere}")
    degrees, minutes = int(match.group(1)), float(match.group(2))
    limit = 90.0 if latitude else 180.0
    angle = degrees + minutes / 60.0
    if minutes >= 60.0 or angle > limit:
        raise NmeaDecodeError(f"angle out of range: {value}")
    return -angle if hemisphere == negative else angle


def _units(text: str) -> None:
    if text not in ("", "M"):
        raise NmeaDecodeError(f"unexpected unit {text!r}")


def _fmt_float(value: float | None, decimals: int) -> str:
    if value is None:
        return ""
    if not math.isfinite(value):
        raise ValueError(f"{value} cannot be sent in NMEA")
    return f"{value:.{decimals}f}"


def _fmt_time(value: dt.time | None) -> str:
    if value is None:
        return ""
    return f"{value.hour:02d}{value.minute:02d}{value.second:02d}.{value.microsecond // 10_000:02d}"


def _fmt_date(value: dt.date | None) -> str:
    if value is None:
        return ""
    if not 1980 <= value.year <= 2079:
        raise ValueError(f"year {value.year} outside the two-digit window 1980..2079")
    return f"{value.day:02d}{value.month:02d}{value.year % 100:02d}"


def _fmt_angle(value: float | None, *, latitude: bool, decimals: int) -> tuple[str, str]:
    if value is None:
        return "", ""
    if not math.isfinite(value):
        raise ValueError(f"{value} cannot be sent in NMEA")
    # Round once in units of 10**-decimals minutes so 59.999995' carries into the degrees.
    scale = 10**decimals
    degrees, minutes = divmod(round(abs(value) * 60 * scale), 60 * scale)
    width = 2 if latitude else 3
    text = f"{degrees:0{width}d}{minutes // scale:02d}.{minutes % scale:0{decimals}d}"
    hemisphere = ("S" if value < 0 else "N") if latitude else ("W" if value < 0 else "E")
    return text, hemisphere


# --- Sentence codecs -----------------------------------------------------------------------


def _parse_gga(talker: str, f: Sequence[str]) -> GGA:
    if len(f) != 14:
        raise NmeaDecodeError(f"GGA has 14 fields, got {len(f)}")
    _units(f[9])
    _units(f[11])
    fix = _int(f[5])
    return GGA(
        talker=talker,
        time=_time(f[0]),
        latitude=_angle(f[1], f[2], latitude=True),
        longitude=_angle(f[3], f[4], latitude=False),
        fix_quality=0 if fix is None else fix,
        satellites=_int(f[6]),
        hdop=_float(f[7]),
        altitude=_float(f[8]),
        geoid_separation=_float(f[10]),
        dgps_age=_float(f[12]),
        dgps_station=_int(f[13]),
    )


def _parse_rmc(talker: str, f: Sequence[str]) -> RMC:
    if not 11 <= len(f) <= 13:
        raise NmeaDecodeError(f"RMC has 11 to 13 fields, got {len(f)}")
    if f[1] not in ("A", "V"):
        raise NmeaDecodeError(f"RMC status {f[1]!r} is not A or V")
    knots = _float(f[6])
    variation = _float(f[9])
    if variation is not None:
        if f[10] not in ("E", "W"):
            raise NmeaDecodeError(f"magnetic variation direction {f[10]!r}")
        variation = -variation if f[10] == "W" else variation
    mode = f[11] if len(f) > 11 and f[11] else None
    return RMC(
        talker=talker,
        time=_time(f[0]),
        valid=f[1] == "A",
        latitude=_angle(f[2], f[3], latitude=True),
        longitude=_angle(f[4], f[5], latitude=False),
        speed=None if knots is None else knots * KNOT_M_S,
        course=_float(f[7]),
        date=_date(f[8]),
        magnetic_variation=variation,
        mode=mode,
    )


def _parse_gsa(talker: str, f: Sequence[str]) -> GSA:
    if not 17 <= len(f) <= 18:
        raise NmeaDecodeError(f"GSA has 17 or 18 fields, got {len(f)}")
    if f[0] not in ("A", "M"):
        raise NmeaDecodeError(f"GSA selection mode {f[0]!r} is not A or M")
    fix_type = _int(f[1])
    if fix_type not in (1, 2, 3):
        raise NmeaDecodeError(f"GSA fix type {f[1]!r} is not 1, 2 or 3")
    ids = tuple(i for i in (_int(x) for x in f[2:14]) if i is not None)
    system = _int(f[17]) if len(f) == 18 and f[17] else None
    return GSA(talker, f[0], fix_type, ids, _float(f[14]), _float(f[15]), _float(f[16]), system)


def _parse_gsv(talker: str, f: Sequence[str]) -> GSV:
    if len(f) < 3:
        raise NmeaDecodeError(f"GSV has at least 3 fields, got {len(f)}")
    count, number, in_view = _int(f[0]), _int(f[1]), _int(f[2])
    if count is None or number is None or in_view is None:
        raise NmeaDecodeError("GSV without message count, number or satellites in view")
    blocks = f[3:]
    signal = None
    if len(blocks) % 4 == 1:  # NMEA 4.1: a trailing signal id
        signal, blocks = blocks[-1] or None, blocks[:-1]
        if signal is not None and not _HEX1_RE.fullmatch(signal):
            raise NmeaDecodeError(f"bad GSV signal id {signal!r}")
    elif len(blocks) % 4:
        raise NmeaDecodeError(f"GSV satellite blocks of 4 fields, got {len(blocks)} fields")
    satellites = []
    for k in range(0, len(blocks), 4):
        prn = _int(blocks[k])
        if prn is None:
            raise NmeaDecodeError("GSV satellite without id")
        satellites.append(
            SatelliteInView(prn, _int(blocks[k + 1]), _int(blocks[k + 2]), _int(blocks[k + 3]))
        )
    return GSV(talker, count, number, in_view, tuple(satellites), signal)


def _parse_gst(talker: str, f: Sequence[str]) -> GST:
    if len(f) != 8:
        raise NmeaDecodeError(f"GST has 8 fields, got {len(f)}")
    return GST(talker, _time(f[0]), *(_float(x) for x in f[1:]))


def decode_sentence(line: str | bytes, *, require_checksum: bool = True) -> Sentence:
    """Decode one sentence (surrounding whitespace/CRLF allowed).

    Raises :class:`NmeaChecksumError` on a checksum mismatch and
    :class:`NmeaDecodeError` for anything else malformed (including a missing
    checksum when ``require_checksum``).
    """
    if isinstance(line, bytes | bytearray):
        try:
            line = bytes(line).decode("ascii")
        except UnicodeDecodeError:
            raise NmeaDecodeError("non-ASCII bytes in sentence") from None
    line = line.strip()
    if not line.startswith("$") or not line.isascii() or not line.isprintable():
        raise NmeaDecodeError("sentence must be printable ASCII starting with '$'")
    body, star, given = line[1:].partition("*")
    if star:
        if not _HEX2_RE.fullmatch(given):
            raise NmeaDecodeError(f"bad checksum field {given!r}")
        if int(given, 16) != checksum(body):
            raise NmeaChecksumError(f"checksum {given} != {checksum(body):02X}")
    elif require_checksum:
        raise NmeaDecodeError("missing checksum")
    if "$" in body:
        raise NmeaDecodeError("'$' inside sentence")
    address, *fields = body.split(",")
    match = _ADDRESS_RE.fullmatch(address)
    if not match:
        raise NmeaDecodeError(f"bad address field {address!r}")
    talker, kind, proprietary = match.groups()
    if proprietary is not None:
        return RawSentence("P", proprietary, tuple(fields))
    try:
        if kind == "GGA":
            return _parse_gga(talker, fields)
        if kind == "RMC":
            return _parse_rmc(talker, fields)
        if kind == "GSA":
            return _parse_gsa(talker, fields)
        if kind == "GSV":
            return _parse_gsv(talker, fields)
        if kind == "GST":
            return _parse_gst(talker, fields)
    except NmeaDecodeError:
        raise
    except ValueError as exc:  # dataclass validation of decoded values
        raise NmeaDecodeError(f"{address}: {exc}") from exc
    return RawSentence(talker, kind, tuple(fields))


def format_gga(gga: GGA, *, minute_decimals: int = 5) -> str:
    """Checksummed GGA sentence with CRLF (time to 0.01 s, lat/lon minutes to 1e-5)."""
    lat, ns = _fmt_angle(gga.latitude, latitude=True, decimals=minute_decimals)
    lon, ew = _fmt_angle(gga.longitude, latitude=False, decimals=minute_decimals)
    fields = (
        _fmt_time(gga.time),
        lat,
        ns,
        lon,
        ew,
        str(gga.fix_quality),
        "" if gga.satellites is None else f"{gga.satellites:02d}",
        _fmt_float(gga.hdop, 2),
        _fmt_float(gga.altitude, 1),
        "M",
        _fmt_float(gga.geoid_separation, 1),
        "M",
        _fmt_float(gga.dgps_age, 1),
        "" if gga.dgps_station is None else f"{gga.dgps_station:04d}",
    )
    return format_sentence(gga.talker + "GGA", fields)


def format_rmc(rmc: RMC, *, minute_decimals: int = 5) -> str:
    """Checksummed RMC sentence with CRLF (speed to 0.001 kn, course to 0.01 deg)."""
    lat, ns = _fmt_angle(rmc.latitude, latitude=True, decimals=minute_decimals)
    lon, ew = _fmt_angle(rmc.longitude, latitude=False, decimals=minute_decimals)
    variation = rmc.magnetic_variation
    fields = [
        _fmt_time(rmc.time),
        "A" if rmc.valid else "V",
        lat,
        ns,
        lon,
        ew,
        _fmt_float(None if rmc.speed is None else rmc.speed / KNOT_M_S, 3),
        _fmt_float(rmc.course, 2),
        _fmt_date(rmc.date),
        _fmt_float(None if variation is None else abs(variation), 1),
        "" if variation is None else ("W" if variation < 0 else "E"),
    ]
    if rmc.mode is not None:
        fields.append(rmc.mode)
    return format_sentence(rmc.talker + "RMC", fields)


def format_gsa(gsa: GSA) -> str:
    """Checksummed GSA sentence with CRLF (DOPs to 0.01; the system id when given)."""
    ids = [f"{i:02d}" for i in gsa.satellites] + [""] * (12 - len(gsa.satellites))
    fields = [gsa.selection, str(gsa.fix_type), *ids]
    fields += [_fmt_float(gsa.pdop, 2), _fmt_float(gsa.hdop, 2), _fmt_float(gsa.vdop, 2)]
    if gsa.system_id is not None:
        fields.append(f"{gsa.system_id:X}")
    return format_sentence(gsa.talker + "GSA", fields)


def format_gsv(gsv: GSV) -> str:
    """Checksummed GSV sentence with CRLF (the signal id when given)."""

    def num(value: int | None, width: int) -> str:
        return "" if value is None else f"{value:0{width}d}"

    fields = [str(gsv.count), str(gsv.number), f"{gsv.in_view:02d}"]
    for sat in gsv.satellites:
        fields += [num(sat.prn, 2), num(sat.elevation, 2), num(sat.azimuth, 3), num(sat.snr, 2)]
    if gsv.signal_id is not None:
        fields.append(gsv.signal_id)
    return format_sentence(gsv.talker + "GSV", fields)


def format_gst(gst: GST) -> str:
    """Checksummed GST sentence with CRLF (values to 0.01 m / 0.1 deg)."""
    fields = [
        _fmt_time(gst.time),
        _fmt_float(gst.rms, 2),
        _fmt_float(gst.major, 2),
        _fmt_float(gst.minor, 2),
        _fmt_float(gst.orientation, 1),
        _fmt_float(gst.latitude_sigma, 2),
        _fmt_float(gst.longitude_sigma, 2),
        _fmt_float(gst.altitude_sigma, 2),
    ]
    return format_sentence(gst.talker + "GST", fields)


# --- Streaming parser ----------------------------------------------------------------------


class NmeaParser:
    """Line-oriented decoder for a byte stream; never raises on garbage.

    Lines end at LF. A *candidate* runs from a ``$`` to the next ``$`` or the end of
    its line. On each line:

    * the candidate that ends the line is decoded (its trailing CR and whitespace
      stripped): ``sentences``, ``checksum_errors`` or ``malformed``; one longer than
      ``max_line`` bytes (``$`` to LF) is not kept and counts as ``malformed``;
    * every byte before that candidate's ``$`` (noise, a sentence cut short by a new
      ``$``) counts in ``garbage_bytes``; this resynchronises after binary noise;
    * a line without ``$`` counts as ``malformed`` unless it is blank.

    The results and counters depend only on the bytes, never on how they are split
    into :meth:`feed` calls, and the buffer never holds more than ``max_line`` bytes.
    """

    def __init__(self, *, max_line: int = 256, require_checksum: bool = True) -> None:
        if max_line < MAX_SENTENCE_LENGTH:
            raise ValueError(f"max_line must be at least {MAX_SENTENCE_LENGTH}")
        self.max_line = max_line
        self.require_checksum = require_checksum
        self._candidate = bytearray()
        """The current candidate from its ``$``, while it is at most ``max_line`` bytes."""
        self._candidate_len = 0
        """Its length so far (0: no ``$`` on this line yet)."""
        self._prefix = 0
        """Bytes of this line before its first ``$``."""
        self._prefix_blank = True
        self.sentences = 0
        self.checksum_errors = 0
        self.malformed = 0
        self.garbage_bytes = 0

    @property
    def buffered(self) -> int:
        return len(self._candidate)

    def reset(self) -> None:
        """Forget the partial line (its bytes are counted in ``garbage_bytes``)."""
        self.garbage_bytes += self._prefix + self._candidate_len
        self._new_line()

    def _new_line(self) -> None:
        self._candidate.clear()
        self._candidate_len = 0
        self._prefix = 0
        self._prefix_blank = True

    def feed(self, data: bytes) -> list[Sentence]:
        """The sentences completed by ``data``, in stream order."""
        out: list[Sentence] = []
        pos = 0
        for match in _DELIMITER_RE.finditer(data):
            at = match.start()
            self._take(data[pos:at])
            if data[at] == _DOLLAR:
                # A new candidate: whatever came before it on this line is garbage.
                self.garbage_bytes += self._candidate_len or self._prefix
                self._prefix = 0
                self._candidate[:] = b"$"
                self._candidate_len = 1
            else:
                self._end_line(out)
            pos = at + 1
        self._take(data[pos:])
        return out

    def _take(self, chunk: bytes) -> None:
        if not chunk:
            return
        if self._candidate_len:
            self._candidate_len += len(chunk)
            if self._candidate_len <= self.max_line:
                self._candidate += chunk
            else:
                self._candidate.clear()  # too long for a sentence: not kept
        else:
            self._prefix += len(chunk)
            if self._prefix_blank and chunk.strip():
                self._prefix_blank = False

    def _end_line(self, out: list[Sentence]) -> None:
        if self._candidate_len > self.max_line:
            self.malformed += 1
        elif self._candidate_len:
            try:
                sentence = decode_sentence(
                    bytes(self._candidate), require_checksum=self.require_checksum
                )
            except NmeaChecksumError:
                self.checksum_errors += 1
            except NmeaDecodeError:
                self.malformed += 1
            else:
                self.sentences += 1
                out.append(sentence)
        elif not self._prefix_blank:
            self.malformed += 1
        self._new_line()
