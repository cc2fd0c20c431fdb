"""docs/protocols.md's NMEA section describes every sentence type the decoder types (GGA,
RMC, GSA, GSV, GST) and says only the others decode to RawSentence (it listed GGA and RMC
alone, so GSA, GSV and GST read as RawSentence; issue 21 point 20)."""

from __future__ import annotations

import re
from pathlib import Path

from openel_serial import nmea

PROTOCOLS = Path(__file__).resolve().parents[2] / "docs" / "protocols.md"

SAMPLES = {  # one real sentence per typed kind (tests/serial/test_nmea_pynmea2.py)
    "GGA": "$GPGGA,092725.00,4717.11399,N,00833.91590,E,1,08,1.01,499.6,M,48.0,M,,*5B",
    "RMC": "$GPRMC,083559.00,A,4717.11437,N,00833.91522,E,0.004,77.52,091202,,,A,V*2D",
    "GSA": "$GPGSA,A,3,23,29,07,08,09,18,26,28,,,,,1.94,1.18,1.54*0D",
    "GSV": "$GPGSV,3,1,10,23,38,230,44,29,71,156,47,07,29,116,41,08,09,081,36*7F",
    "GST": "$GNGST,103607.00,38,60,38,89,15,24,31*63",
}


def _nmea_section() -> str:
    text = PROTOCOLS.read_text(encoding="utf-8")
    start = text.index("## NMEA 0183")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else len(text)]


def test_every_typed_sentence_is_documented_and_only_the_others_are_raw() -> None:
    section = _nmea_section()
    typed = set()
    for kind, sentence in SAMPLES.items():
        decoded = nmea.decode_sentence(sentence)
        assert type(decoded).__name__ == kind  # typed, not a RawSentence
        typed.add(kind)
    bullets = set(re.findall(r"^\* \*\*([A-Z]{3}) \(", section, flags=re.M))
    assert bullets == typed
    raw = next(line for line in section.split("\n* ") if line.startswith("**Other sentence"))
    assert all(kind in raw for kind in typed)  # "any type but GGA, RMC, GSA, GSV and GST"
    assert "any type but" in raw
    assert isinstance(
        nmea.decode_sentence("$GPVTG,77.52,T,,M,0.004,N,0.008,K,A*06"), nmea.RawSentence
    )
