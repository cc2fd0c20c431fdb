"""NMEA 0183 codec: classic sentences, checksum, round trips, stream parsing."""

from __future__ import annotations

import contextlib
import datetime as dt
import math
from functools import reduce

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_serial import nmea
from openel_serial.errors import NmeaChecksumError, NmeaDecodeError

CLASSIC_GGA = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"
CLASSIC_RMC = "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A"
GGA_MS = "$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76"
RMC_MODE = "$GPRMC,092750.000,A,5321.6802,N,00630.3372,W,0.02,31.66,280511,,,A*43"


def _xor(body: str) -> int:
    return reduce(lambda acc, ch: acc ^ ord(ch), body, 0)


def test_checksum() -> None:
    for sentence in (CLASSIC_GGA, CLASSIC_RMC, GGA_MS, RMC_MODE):
        body, given_sum = sentence[1:].split("*")
        assert nmea.checksum(body) == _xor(body) == int(given_sum, 16)


def test_classic_gga() -> None:
    gga = nmea.decode_sentence(CLASSIC_GGA)
    assert isinstance(gga, nmea.GGA)
    assert gga.latitude == pytest.approx(48 + 7.038 / 60)
    assert gga.longitude == pytest.approx(11 + 31.0 / 60)
    assert gga == nmea.GGA(
        talker="GP",
        time=dt.time(12, 35, 19),
        latitude=gga.latitude,
        longitude=gga.longitude,
        fix_quality=nmea.FixQuality.GPS,
        satellites=8,
        hdop=0.9,
        altitude=545.4,
        geoid_separation=46.9,
    )


def test_classic_rmc() -> None:
    rmc = nmea.decode_sentence(CLASSIC_RMC + "\r\n")
    assert isinstance(rmc, nmea.RMC)
    assert rmc.valid and rmc.time == dt.time(12, 35, 19)
    assert rmc.date == dt.date(1994, 3, 23)
    assert rmc.speed == pytest.approx(22.4 * 1852 / 3600)
    assert rmc.course == 84.4
    assert rmc.course_rad == pytest.approx(math.radians(84.4))
    assert rmc.magnetic_variation == -3.1
    assert rmc.mode is None


def test_southern_western_and_fractional_time() -> None:
    gga = nmea.decode_sentence(GGA_MS)
    assert isinstance(gga, nmea.GGA)
    assert gga.longitude == pytest.approx(-(6 + 30.3372 / 60))
    assert gga.time == dt.time(9, 27, 50)
    rmc = nmea.decode_sentence(RMC_MODE)
    assert isinstance(rmc, nmea.RMC)
    assert rmc.mode == "A" and rmc.date == dt.date(2011, 5, 28)
    assert rmc.magnetic_variation is None


def test_any_talker_and_other_sentences() -> None:
    sentence = nmea.format_sentence("GNGGA", CLASSIC_GGA[7:].split("*")[0].split(","))
    gga = nmea.decode_sentence(sentence)
    assert isinstance(gga, nmea.GGA) and gga.talker == "GN"
    gsv = nmea.decode_sentence(nmea.format_sentence("GLGSV", ["1", "1", "00"]))
    assert isinstance(gsv, nmea.GSV) and gsv.talker == "GL" and gsv.in_view == 0
    zda = nmea.decode_sentence(nmea.format_sentence("GNZDA", ["120000.00", "01", "01", "2026"]))
    assert zda == nmea.RawSentence("GN", "ZDA", ("120000.00", "01", "01", "2026"))
    pubx = nmea.decode_sentence(nmea.format_sentence("PUBX", ["00", "x"]))
    assert pubx == nmea.RawSentence("P", "UBX", ("00", "x"))


def test_no_fix_sentence() -> None:
    gga = nmea.decode_sentence(nmea.format_sentence("GPGGA", [""] * 5 + ["0"] + [""] * 8))
    assert gga == nmea.GGA()
    rmc = nmea.decode_sentence(nmea.format_sentence("GPRMC", ["", "V"] + [""] * 9))
    assert rmc == nmea.RMC()


def test_format_exact() -> None:
    gga = nmea.GGA(
        talker="GP",
        time=dt.time(12, 35, 19),
        latitude=48.1173,
        longitude=11.516666666666667,
        fix_quality=1,
        satellites=8,
        hdop=0.9,
        altitude=545.4,
        geoid_separation=46.9,
    )
    text = nmea.format_gga(gga)
    assert text == "$GPGGA,123519.00,4807.03800,N,01131.00000,E,1,08,0.90,545.4,M,46.9,M,,*59\r\n"
    assert _xor(text[1:-5]) == 0x59
    assert len(text) <= nmea.MAX_SENTENCE_LENGTH
    rmc = nmea.RMC(latitude=-0.5, longitude=-179.99999999, valid=True, speed=0.0)
    assert nmea.format_rmc(rmc).startswith("$GPRMC,,A,0030.00000,S,18000.00000,W,0.000,")


@pytest.mark.parametrize(
    "line",
    [
        CLASSIC_GGA[:-2] + "48",  # wrong checksum
        CLASSIC_GGA.replace("4807.038", "4807.039"),  # body changed, checksum kept
    ],
)
def test_checksum_mismatch(line: str) -> None:
    with pytest.raises(NmeaChecksumError):
        nmea.decode_sentence(line)


@given(st.sampled_from([CLASSIC_GGA, CLASSIC_RMC, GGA_MS, RMC_MODE]), st.data())
def test_any_single_character_corruption_is_detected(sentence: str, data: st.DataObject) -> None:
    star = sentence.index("*")
    pos = data.draw(st.integers(1, star - 1))
    char = data.draw(
        st.characters(min_codepoint=0x20, max_codepoint=0x7E).filter(
            lambda c: c not in "$*" and c != sentence[pos]
        )
    )
    with pytest.raises(NmeaChecksumError):
        nmea.decode_sentence(sentence[:pos] + char + sentence[pos + 1 :])


@pytest.mark.parametrize(
    "line",
    [
        "",
        "GPGGA,1*00",
        "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,",  # no checksum
        nmea.format_sentence("GPGGA", ["1"] * 3),  # wrong field count
        nmea.format_sentence("GPGGA", ["126019", *[""] * 4, "0", *[""] * 8]),  # minute 60
        nmea.format_sentence("GPGGA", ["", "9100.0", "N", "", "", "0", *[""] * 8]),  # lat > 90
        nmea.format_sentence("GPGGA", ["", "4807.038", "X", "", "", "0", *[""] * 8]),
        nmea.format_sentence("GPGGA", ["", "", "", "", "", "0", "1_0", *[""] * 7]),
        nmea.format_sentence("GPRMC", ["", "X", *[""] * 9]),  # bad status
        nmea.format_sentence("GPRMC", ["", "A", *[""] * 6, "310299", "", ""]),  # 31 Feb
        nmea.format_sentence("gpgga", []),
        "$GPGGA,1*4G",
    ],
)
def test_malformed(line: str) -> None:
    with pytest.raises(NmeaDecodeError):
        nmea.decode_sentence(line)


def test_checksum_optional_when_allowed() -> None:
    bare = CLASSIC_GGA.split("*")[0]
    assert nmea.decode_sentence(bare, require_checksum=False) == nmea.decode_sentence(CLASSIC_GGA)


talkers = st.sampled_from(["GP", "GN", "GL", "GA", "GB", "BD"])
times = st.builds(
    dt.time,
    st.integers(0, 23),
    st.integers(0, 59),
    st.integers(0, 59),
    st.integers(0, 99).map(lambda cs: cs * 10_000),
)
lats = st.floats(-90.0, 90.0)
lons = st.floats(-180.0, 180.0)
ANGLE_TOL = 0.5e-5 / 60 + 1e-12  # half a unit of the 5th decimal of a minute


@given(
    talkers,
    st.none() | times,
    st.none() | lats,
    st.none() | lons,
    st.integers(0, 8),
    st.none() | st.integers(0, 99),
    st.none() | st.floats(0.0, 99.0),
    st.none() | st.floats(-1000.0, 20000.0),
    st.none() | st.floats(-200.0, 200.0),
    st.none() | st.floats(0.0, 999.0),
    st.none() | st.integers(0, 1023),
)
def test_gga_round_trip(
    talker: str,
    time: dt.time | None,
    lat: float | None,
    lon: float | None,
    fix: int,
    sats: int | None,
    hdop: float | None,
    alt: float | None,
    sep: float | None,
    age: float | None,
    station: int | None,
) -> None:
    gga = nmea.GGA(talker, time, lat, lon, fix, sats, hdop, alt, sep, age, station)
    text = nmea.format_gga(gga)
    assert text.endswith("\r\n")
    got = nmea.decode_sentence(text)
    assert isinstance(got, nmea.GGA)
    assert (got.talker, got.time, got.fix_quality, got.satellites, got.dgps_station) == (
        talker,
        time,
        fix,
        sats,
        station,
    )
    _close(got.latitude, lat, ANGLE_TOL)
    _close(got.longitude, lon, ANGLE_TOL)
    _close(got.hdop, hdop, 0.005)
    _close(got.altitude, alt, 0.05)
    _close(got.geoid_separation, sep, 0.05)
    _close(got.dgps_age, age, 0.05)


@given(
    talkers,
    st.none() | times,
    st.booleans(),
    st.none() | lats,
    st.none() | lons,
    st.none() | st.floats(0.0, 500.0),
    st.none() | st.floats(0.0, 359.99),
    st.none() | st.dates(dt.date(1980, 1, 1), dt.date(2079, 12, 31)),
    st.none() | st.floats(-180.0, 180.0),
    st.none() | st.sampled_from("ADEFMNPRS"),
)
def test_rmc_round_trip(
    talker: str,
    time: dt.time | None,
    valid: bool,
    lat: float | None,
    lon: float | None,
    speed: float | None,
    course: float | None,
    date: dt.date | None,
    variation: float | None,
    mode: str | None,
) -> None:
    rmc = nmea.RMC(talker, time, valid, lat, lon, speed, course, date, variation, mode)
    got = nmea.decode_sentence(nmea.format_rmc(rmc))
    assert isinstance(got, nmea.RMC)
    assert (got.talker, got.time, got.valid, got.date, got.mode) == (
        talker,
        time,
        valid,
        date,
        mode,
    )
    _close(got.latitude, lat, ANGLE_TOL)
    _close(got.longitude, lon, ANGLE_TOL)
    _close(got.speed, speed, 0.0005 * nmea.KNOT_M_S + 1e-9)
    _close(got.course, course, 0.005)
    _close(got.magnetic_variation, variation, 0.05)


def _close(got: float | None, want: float | None, tol: float) -> None:
    """``tol``: half the last printed digit (0.75 printed with one decimal is 0.8, off by
    0.05 plus the binary rounding of 0.75 - 0.8)."""
    if want is None:
        assert got is None
    else:
        assert got is not None and abs(got - want) <= tol * (1 + 1e-9)


@given(st.text(max_size=100) | st.binary(max_size=100))
def test_random_input_raises_only_decode_error(line: str | bytes) -> None:
    with contextlib.suppress(NmeaDecodeError):
        nmea.decode_sentence(line)


fieldtext = st.text(
    st.characters(min_codepoint=0x20, max_codepoint=0x7E).filter(lambda c: c not in "$*,!"),
    max_size=12,
)


@given(st.sampled_from(["GPGGA", "GNRMC", "GPRMC", "GLGGA"]), st.lists(fieldtext, max_size=15))
def test_random_fields_with_valid_checksum(address: str, fields: list[str]) -> None:
    try:
        nmea.decode_sentence(nmea.format_sentence(address, fields))
    except NmeaChecksumError:
        pytest.fail("checksum was valid")
    except NmeaDecodeError:
        pass


# --- streaming parser ----------------------------------------------------------------------

noise = st.binary(max_size=20).map(lambda b: b.replace(b"\n", b"").replace(b"$", b""))


@given(
    st.lists(st.tuples(noise, st.sampled_from([CLASSIC_GGA, CLASSIC_RMC, GGA_MS, RMC_MODE]))),
    st.data(),
)
def test_parser_recovers_sentences(parts: list[tuple[bytes, str]], data: st.DataObject) -> None:
    stream = b"".join(junk + s.encode() + b"\r\n" for junk, s in parts)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    parser = nmea.NmeaParser()
    got: list[nmea.Sentence] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += parser.feed(stream[start:end])
    assert got == [nmea.decode_sentence(s) for _, s in parts]
    assert parser.sentences == len(parts)
    assert parser.checksum_errors == 0


def test_parser_counts_errors() -> None:
    parser = nmea.NmeaParser()
    bad = CLASSIC_GGA[:-2] + "00"
    malformed = nmea.format_sentence("GPGGA", ["x"])  # valid checksum, wrong fields
    got = parser.feed(f"{bad}\r\nhello\r\n{malformed}\r\n{CLASSIC_RMC}\r\n".encode())
    assert len(got) == 1 and isinstance(got[0], nmea.RMC)
    assert (parser.checksum_errors, parser.malformed, parser.sentences) == (1, 2, 1)


@given(st.lists(st.binary(max_size=300), max_size=10))
def test_parser_never_raises_and_stays_bounded(chunks: list[bytes]) -> None:
    parser = nmea.NmeaParser(max_line=100)
    for chunk in chunks:
        parser.feed(chunk)
        assert parser.buffered <= 100
    parser.feed(b"\n" + CLASSIC_GGA.encode() + b"\r\n")
    assert parser.sentences >= 1


# --- fuzzing the stream parser: read boundaries never change the outcome ---------------------


def _parse_nmea(
    stream: bytes, cuts: list[int], max_line: int
) -> tuple[list[nmea.Sentence], tuple[int, ...]]:
    parser = nmea.NmeaParser(max_line=max_line)
    got: list[nmea.Sentence] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += parser.feed(stream[start:end])
        assert parser.buffered <= max_line
    counters = (
        parser.sentences,
        parser.checksum_errors,
        parser.malformed,
        parser.garbage_bytes,
        parser.buffered,
    )
    return got, counters


VALID = [CLASSIC_GGA, CLASSIC_RMC, GGA_MS, RMC_MODE]
nmea_segments = st.one_of(
    st.sampled_from(VALID).map(lambda s: s.encode() + b"\r\n"),
    st.sampled_from(VALID).map(lambda s: s[:-2].encode() + b"00\r\n"),  # bad checksum
    st.builds(lambda s, n: s.encode()[:n], st.sampled_from(VALID), st.integers(0, 80)),  # cut short
    st.sampled_from([b"$", b"\r\n", b"\n", b"\r", b"*", b",", b" "]),
    st.binary(max_size=30),
    st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), min_size=40, max_size=140).map(
        str.encode
    ),  # long printable runs: lines over max_line
    st.builds(  # long sentences with a valid checksum
        lambda n: nmea.format_sentence("GPTXT", ["x" * n]).encode(), st.integers(60, 200)
    ),
)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(nmea_segments, max_size=12).map(b"".join),
    st.data(),
    st.sampled_from([nmea.MAX_SENTENCE_LENGTH, 120, 256]),
)
def test_fuzz_parser_split_anywhere_parses_as_whole(
    stream: bytes, data: st.DataObject, max_line: int
) -> None:
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    whole = _parse_nmea(stream, [], max_line)
    assert _parse_nmea(stream, cuts, max_line) == whole
    assert _parse_nmea(stream, list(range(1, len(stream))), max_line) == whole


def test_overlong_sentence_is_malformed_however_it_is_read() -> None:
    # A valid sentence longer than max_line: counted as malformed whether it arrives in
    # one read or in two (it used to be decoded whole but dropped when split).
    sentence = nmea.format_sentence("GPTXT", ["y" * 150]).encode()
    for cut in (len(sentence), 120, 10):
        parser = nmea.NmeaParser(max_line=100)
        got = parser.feed(sentence[:cut]) + parser.feed(sentence[cut:])
        assert got == []
        assert (parser.malformed, parser.garbage_bytes, parser.buffered) == (1, 0, 0)
    short = nmea.format_sentence("GPTXT", ["y" * 50]).encode()
    parser = nmea.NmeaParser(max_line=100)
    assert parser.feed(short[:30]) + parser.feed(short[30:]) == [nmea.decode_sentence(short)]


def test_garbage_before_a_sentence_is_counted_byte_for_byte() -> None:
    parser = nmea.NmeaParser()
    noise = b"\x00\x13$GPG\xffjunk"  # includes a sentence cut short by the next '$'
    got = parser.feed(noise + CLASSIC_GGA.encode() + b"\r\nno dollar here\r\n\r\n")
    assert got == [nmea.decode_sentence(CLASSIC_GGA)]
    assert (parser.garbage_bytes, parser.malformed, parser.sentences) == (len(noise), 1, 1)
    parser.feed(b"$GPRMC,1234")
    parser.reset()  # a partial sentence forgotten on reconnect is counted, not lost untold
    assert parser.garbage_bytes == len(noise) + len(b"$GPRMC,1234") and parser.buffered == 0


@settings(max_examples=100, deadline=None)
@given(st.lists(nmea_segments, max_size=4).map(b"".join) | st.binary(max_size=120))
def test_fuzz_decode_raises_only_nmea_decode_error(line: bytes) -> None:
    try:
        sentence = nmea.decode_sentence(line)
    except NmeaDecodeError:
        return
    assert isinstance(sentence, nmea.GGA | nmea.RMC | nmea.RawSentence)
