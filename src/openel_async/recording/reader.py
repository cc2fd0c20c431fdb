"""Reading a recording back: its channels and messages, even from a file whose writer was
killed (read up to the last complete chunk), and the summary ``openel-async record info``
prints.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

__all__ = [
    "NotMcapError",
    "RecordedChannel",
    "RecordedMessage",
    "Recording",
    "info_lines",
    "read_recording",
]


@dataclass(frozen=True, slots=True)
class RecordedChannel:
    id: int
    topic: str
    schema: str
    metadata: dict[str, str]


@dataclass(frozen=True, slots=True)
class RecordedMessage:
    topic: str
    log_time_ns: int
    data: dict[str, Any]


@dataclass
class Recording:
    """A recording's content (see :func:`read_recording`)."""

    path: Path
    channels: dict[int, RecordedChannel] = field(default_factory=dict)
    messages: list[RecordedMessage] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False
    """False: the file ends before its footer (the writer was killed); what was read is what
    the last complete chunk held."""
    problem: str = ""

    def topic(self, topic: str) -> list[dict[str, Any]]:
        """The messages of ``topic``, in order."""
        return [m.data for m in self.messages if m.topic == topic]

    def counts(self) -> Counter[str]:
        return Counter(m.topic for m in self.messages)

    @property
    def dropped(self) -> int | None:
        """Messages the recorder dropped (None: not known, the file was cut)."""
        stats = self.metadata.get("openel_async.recorder")
        return None if stats is None else int(stats["dropped"])

    def iter_topic_prefix(self, prefix: str) -> Iterator[tuple[str, dict[str, Any]]]:
        for m in self.messages:
            if m.topic.startswith(prefix):
                yield m.topic, m.data


MAGIC = b"\x89MCAP0\r\n"
"""The first bytes of every MCAP file."""


class NotMcapError(ValueError):
    """The file is not an MCAP file (it does not begin with the MCAP magic)."""


def read_recording(path: str | os.PathLike[str]) -> Recording:
    """Every channel and message of the MCAP file ``path``, in file order; a file cut short
    is read up to its last complete record (``complete`` False). Raises
    :class:`NotMcapError` for a file that is not MCAP at all."""
    out = Recording(Path(path))
    schemas: dict[int, str] = {}
    with open(out.path, "rb") as f:
        head = f.read(len(MAGIC))
        if head != MAGIC:
            what = "it is empty" if not head else "it does not begin with the MCAP magic"
            raise NotMcapError(f"{out.path}: not an MCAP file ({what})")
        f.seek(0)
        reader = StreamReader(f, skip_magic=False)
        try:
            for record in reader.records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    out.channels[record.id] = RecordedChannel(
                        record.id, record.topic, schemas.get(record.schema_id, ""),
                        dict(record.metadata),
                    )  # fmt: skip
                elif isinstance(record, Message):
                    channel = out.channels.get(record.channel_id)
                    if channel is not None:
                        out.messages.append(
                            RecordedMessage(channel.topic, record.log_time, json.loads(record.data))
                        )
                elif isinstance(record, Metadata):
                    out.metadata[record.name] = dict(record.metadata)
            out.complete = True
        except (McapError, EOFError, ValueError, OSError) as exc:
            out.problem = f"{type(exc).__name__}: {exc}"
        except Exception as exc:  # a cut inside a record: struct errors, zstd errors...
            out.problem = f"{type(exc).__name__}: {exc}"
    return out


def info_lines(recording: Recording) -> list[str]:
    """What ``openel-async record info`` prints."""
    msgs = recording.messages
    lines = [f"file        {recording.path}"]
    if msgs:
        start = min(m.log_time_ns for m in msgs)
        end = max(m.log_time_ns for m in msgs)
        lines.append(f"duration    {(end - start) / 1e9:.3f} s ({len(msgs)} messages)")
    else:
        lines.append("duration    0 s (no messages)")
    if recording.complete:
        dropped = recording.dropped
        lines.append(
            "complete    yes" + ("" if dropped is None else f", {dropped} message(s) dropped")
        )
    else:
        lines.append(f"complete    no: cut short ({recording.problem}); read to the last chunk")
    run = recording.metadata.get("openel_async.run")
    if run:
        lines.append("run         " + ", ".join(f"{k}={v}" for k, v in sorted(run.items())))
    counts = recording.counts()
    width = max((len(c.topic) for c in recording.channels.values()), default=5) + 2
    lines.append(f"channels    {len(recording.channels)}")
    for channel in sorted(recording.channels.values(), key=lambda c: c.topic):
        kinds = Counter(
            str(m.data.get("kind")) for m in msgs if m.topic == channel.topic and "kind" in m.data
        )
        detail = ", ".join(f"{k} {n}" for k, n in sorted(kinds.items()))
        lines.append(
            f"  {channel.topic:{width}}{counts[channel.topic]:8d}  {channel.schema}"
            + (f"  ({detail})" if detail else "")
        )
    return lines
