"""The simulated NMEA 0183 GPS receiver on a pseudo-terminal (re-exported by
:mod:`openel_serial.peers`).

:class:`SimGps`: GGA + RMC (``extended``: + GSA, GSV, GST) at ``rate_hz`` along a
:class:`GpsPath`, answering MediaTek's ``$PMTK220`` rate command; injection of checksum
errors, garbage, silence (pause), loss of fix (``inject_fault``) and unplug/plug.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Final

import anyio

from openel_async.clock import Clock
from openel_async.logs import get_logger
from openel_serial import nmea

from .ptypeer import PtyPeer

__all__ = ["EARTH_RADIUS_M", "GpsPath", "SimGps"]

log = get_logger(__name__)

NS: Final = 1_000_000_000

EARTH_RADIUS_M: Final = 6_371_000.0


@dataclass(frozen=True, slots=True)
class GpsPath:
    """A straight track at constant speed and course from a start point (flat earth)."""

    latitude: float = 35.681236
    longitude: float = 139.767125
    altitude: float = 40.0
    speed: float = 5.0
    """m/s."""
    course: float = 45.0
    """degrees true."""

    def at(self, t_s: float) -> tuple[float, float, float]:
        """(latitude, longitude, altitude) in degrees and metres after ``t_s`` seconds."""
        distance = self.speed * t_s
        north = distance * math.cos(math.radians(self.course))
        east = distance * math.sin(math.radians(self.course))
        lat = self.latitude + math.degrees(north / EARTH_RADIUS_M)
        lon = self.longitude + math.degrees(
            east / (EARTH_RADIUS_M * math.cos(math.radians(self.latitude)))
        )
        return lat, lon, self.altitude


class SimGps(PtyPeer):
    """A GPS receiver behind a pty: GGA then RMC (``extended``: GGA, GSA, GSV, RMC, GST)
    every output period, answering MediaTek's ``$PMTK220`` rate command.

    Epoch k is sent at start + k periods (on ``clock``) and describes the receiver at
    ``start_utc`` + the same time on ``track``. ``$PMTK220,<ms>`` (100..10000 ms) changes
    the period from the next epoch on and is acknowledged with ``$PMTK001,220,3``; out of
    range: ``$PMTK001,220,2``; another PMTK command: ``$PMTK001,<cmd>,1`` (unsupported).
    ``pmtk=False`` models a receiver of another family, which ignores the commands.
    Output nobody reads is dropped, as a UART would.
    """

    def __init__(
        self,
        *,
        rate_hz: float = 1.0,
        track: GpsPath | None = None,
        start_utc: dt.datetime | None = None,
        talker: str = "GP",
        fix_quality: int = nmea.FixQuality.GPS,
        satellites: int = 9,
        hdop: float = 0.9,
        geoid_separation: float | None = 39.5,
        extended: bool = False,
        snr: tuple[int, ...] = (45, 42, 40, 38, 36, 33, 30, 28, 25),
        sigma: tuple[float, float] | None = (1.5, 2.0),
        pmtk: bool = True,
        baudrate: int | None = None,
        path: str | Path | None = None,
        clock: Clock | None = None,
    ) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz {rate_hz} must be > 0")
        super().__init__(path, clock)
        self.rate_hz = rate_hz
        self.baudrate = baudrate
        """The receiver's UART rate: a host whose tty is set to another rate reads garbage
        (no whole sentence), as on a real port; None: any rate (a pty has none)."""
        self.track = track or GpsPath()
        self.start_utc = start_utc or dt.datetime(2024, 5, 1, 12, 0, 0, tzinfo=dt.UTC)
        self.talker = talker
        self.fix_quality = fix_quality
        self.satellites = satellites
        self.hdop = hdop
        self.geoid_separation = geoid_separation
        self.extended = extended
        self.snr = snr
        """C/N0 (dB-Hz) of the satellites in view (GSV), one per satellite."""
        self.sigma = sigma
        """GST's (latitude, longitude) standard deviations in m; None: no GST."""
        self.pmtk = pmtk
        self.corrupt_checksums = 0
        """Sentences still to be sent with a wrong checksum."""
        self.paused = False
        """True: the receiver is silent (epochs are skipped)."""
        self.fault_reason: str | None = None
        """The reason of the last :meth:`inject_fault`."""
        self.epochs = 0
        self.sentences = 0
        self.corrupted = 0
        self.commands: list[str] = []
        """Sentences received from the driver (e.g. ``$PMTK220,200*2C``)."""
        self._epoch = 0
        self._t_s = 0.0
        self._wake: anyio.CancelScope | None = None

    @property
    def period_ms(self) -> float:
        return 1000.0 / self.rate_hz

    def sentences_for(self, epoch: int) -> list[str]:
        """The sentences of epoch ``epoch`` at the current rate (checksummed, CRLF)."""
        return self._sentences_at(epoch / self.rate_hz)

    def _sentences_at(self, t: float) -> list[str]:
        utc = self.start_utc + dt.timedelta(seconds=t)
        lat, lon, alt = self.track.at(t)
        valid = self.fix_quality > 0
        time = utc.time().replace(tzinfo=None)
        gga = nmea.GGA(
            talker=self.talker,
            time=time,
            latitude=lat if valid else None,
            longitude=lon if valid else None,
            fix_quality=self.fix_quality,
            satellites=self.satellites,
            hdop=self.hdop,
            altitude=alt if valid else None,
            geoid_separation=self.geoid_separation,
        )
        rmc = nmea.RMC(
            talker=self.talker,
            time=time,
            valid=valid,
            latitude=lat if valid else None,
            longitude=lon if valid else None,
            speed=self.track.speed if valid else None,
            course=self.track.course if valid else None,
            date=utc.date(),
            mode="A" if valid else "N",
        )
        if not self.extended:
            return [nmea.format_gga(gga), nmea.format_rmc(rmc)]
        used = tuple(range(1, min(self.satellites, len(self.snr), 12) + 1)) if valid else ()
        gsa = nmea.GSA(
            self.talker,
            "A",
            3 if valid else 1,
            used,
            self.hdop * 1.6 if valid else None,
            self.hdop if valid else None,
            self.hdop * 1.3 if valid else None,
        )
        sats = [
            nmea.SatelliteInView(k + 1, 10 + 7 * k % 80, 40 * k % 360, snr)
            for k, snr in enumerate(self.snr)
        ]
        count = max(1, math.ceil(len(sats) / 4))
        gsv = [
            nmea.format_gsv(
                nmea.GSV(self.talker, count, n + 1, len(sats), tuple(sats[4 * n : 4 * n + 4]))
            )
            for n in range(count)
        ]
        out = [nmea.format_gga(gga), nmea.format_gsa(gsa), *gsv, nmea.format_rmc(rmc)]
        if self.sigma is not None and valid:
            lat_s, lon_s = self.sigma
            gst = nmea.GST(self.talker, time, 3.0, max(lat_s, lon_s), min(lat_s, lon_s), 0.0)
            out.append(nmea.format_gst(replace(gst, latitude_sigma=lat_s, longitude_sigma=lon_s)))
        return out

    async def _serve(self) -> None:
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._listen)
            await self._send()

    async def _send(self) -> None:
        clock = self.clock
        next_ns = clock.now_ns()
        while True:
            if not self.paused:
                out = []
                for sentence in self._sentences_at(self._t_s):
                    if self.corrupt_checksums:
                        self.corrupt_checksums -= 1
                        self.corrupted += 1
                        body, _, given = sentence.rstrip("\r\n").rpartition("*")
                        sentence = f"{body}*{int(given, 16) ^ 0x5A:02X}\r\n"
                    out.append(sentence)
                self.pty.write_nowait(self._on_the_wire("".join(out).encode("ascii")))
                self.epochs += 1
                self.sentences += len(out)
            self._epoch += 1
            sent_ns = next_ns
            period_s = 1.0 / self.rate_hz
            self._t_s += period_s
            next_ns = sent_ns + round(NS * period_s)
            with anyio.CancelScope() as self._wake:
                await clock.sleep_until(next_ns)
            self._wake = None
            if period_s != 1.0 / self.rate_hz:  # the rate changed while waiting
                self._t_s += 1.0 / self.rate_hz - period_s
                next_ns = sent_ns + round(NS / self.rate_hz)
                if next_ns > clock.now_ns():
                    await clock.sleep_until(next_ns)

    def _on_the_wire(self, data: bytes) -> bytes:
        """``data`` as the host's UART decodes it: garbage at another rate than the
        receiver's (framing errors: no ``$`` survives, nor a line end)."""
        host = self.pty.baudrate()
        if self.baudrate is None or host is None or host == self.baudrate:
            return data
        return bytes(0x80 | (b * 7 + host) & 0x7F for b in data)

    async def _listen(self) -> None:
        parser = nmea.NmeaParser()
        while True:
            for sentence in parser.feed(await self.pty.read()):
                if isinstance(sentence, nmea.RawSentence) and sentence.talker == "P":
                    self._command(sentence)

    def _command(self, sentence: nmea.RawSentence) -> None:
        text = nmea.format_sentence("P" + sentence.sentence_type, sentence.fields).strip()
        self.commands.append(text)
        if not self.pmtk or not sentence.sentence_type.startswith("MTK"):
            return
        command = sentence.sentence_type[3:]
        flag = 1
        if command == "220":
            period = sentence.fields[0] if sentence.fields else ""
            flag = 2
            if period.isdigit() and 100 <= int(period) <= 10_000:
                flag = 3
                self.rate_hz = 1000.0 / int(period)
                if self._wake is not None:
                    self._wake.cancel()
        ack = nmea.format_sentence("PMTK001", [command, str(flag)])
        self.pty.write_nowait(ack.encode("ascii"))

    def inject_garbage(self, data: bytes = b"\x00\xff$GPG\x13garbage\r\n") -> None:
        """Send noise to the driver now."""
        self.pty.write_nowait(data)

    def inject_fault(self, reason: str) -> None:
        """Lose the fix (``openel_async.rig.FaultInjection``), as on an antenna fault: from
        the next epoch on, GGA fix quality 0 and RMC status V, without a position; the
        driver keeps the last fix and reports it stale. Callable from any thread (the
        serving task reads the attributes at each epoch); ``fix_quality`` set back to 1
        restores the fix."""
        log.info("sim_gps_fault_injected", reason=reason)
        self.fault_reason = reason
        self.fix_quality = nmea.FixQuality.INVALID
