"""The writer process of the recorder and the live view: it reads the control loop's records
from its stdin and writes them as JSON messages to an MCAP file (:class:`~.recorder.McapSink`)
and/or publishes them on a Foxglove WebSocket server (:class:`~.live.FoxgloveSink`).

Running in a process of its own, encoding and writing never compete with the control loop for
the interpreter lock: the application only appends tuples to a queue. The parent
(:class:`~.pipeline.Pipeline`) sends frames: a 4-byte little-endian length, then a msgpack
list of entries (:data:`KINDS` below). When its stdin closes -- the parent finished or was
killed -- the process writes what it received, closes the MCAP file (summary and footer) and
exits. It prints one JSON line when ready (``{"port": N}``: the WebSocket port).

``python -m openel_async.recording.sink_process [--mcap PATH] [--foxglove HOST:PORT]
[--chunk-size BYTES]``
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import Any, BinaryIO

import msgspec
import structlog

from .pipeline import PipelineStats
from .records import CHANNEL, HEADER, SCHEMAS, STATS, to_message
from .schemas import ChannelSpec, Schema


def serve(stream: BinaryIO, sinks: list[Any], schemas: dict[str, Schema]) -> PipelineStats:
    """Write every entry of ``stream`` to ``sinks`` until it ends (or is cut)."""
    decode = msgspec.msgpack.Decoder().decode
    encode = msgspec.json.Encoder().encode
    channels: dict[int, ChannelSpec] = {}
    offsets: dict[int, int] = {}
    written = queued = dropped = capacity = 0
    read = stream.read
    while True:
        header = read(4)
        if len(header) < 4:
            break
        (size,) = HEADER.unpack(header)
        payload = read(size)
        if len(payload) < size:  # the parent died mid-frame
            break
        for entry in decode(payload):
            channel = entry[0]
            if channel == CHANNEL:
                _, offset, _, cid, topic, schema_name, metadata = entry
                spec = ChannelSpec(cid, topic, schemas[schema_name], metadata)
                channels[cid] = spec
                offsets[cid] = offset
                for sink in sinks:
                    sink.add_channel(spec)
                continue
            if channel == STATS:
                _, queued, dropped, capacity = entry
                continue
            data = encode(to_message(entry))
            spec = channels[channel]
            log_time = entry[1] + offsets[channel]
            for sink in sinks:
                sink.write(spec, log_time, data)
            written += 1
        for sink in sinks:
            sink.flush()
    return PipelineStats(queued or written, written, dropped, capacity)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="openel_async.recording.sink_process")
    parser.add_argument("--mcap", default=None)
    parser.add_argument("--foxglove", default=None, metavar="HOST:PORT")
    parser.add_argument("--chunk-size", type=int, default=64 * 1024)
    args = parser.parse_args(argv)
    # stdout carries the ready line: the log goes to stderr.
    structlog.configure(logger_factory=structlog.PrintLoggerFactory(sys.stderr))
    sinks: list[Any] = []
    info: dict[str, Any] = {}
    try:
        if args.mcap is not None:
            from .recorder import McapSink

            sinks.append(McapSink(args.mcap, chunk_size=args.chunk_size))
        if args.foxglove is not None:
            from .live import FoxgloveSink

            host, _, port = args.foxglove.rpartition(":")
            live = FoxgloveSink(host=host, port=int(port))
            sinks.append(live)
            info["port"] = live.port
    except Exception as exc:
        print(json.dumps({"error": f"{type(exc).__name__}: {exc}"}), flush=True)
        for sink in sinks:
            sink.close(PipelineStats(0, 0, 0, 0))
        return 1
    print(json.dumps(info), flush=True)
    close: list[Callable[[PipelineStats], None]] = [sink.close for sink in sinks]
    stats = serve(sys.stdin.buffer, sinks, SCHEMAS)
    for done in close:
        done(stats)
    print(json.dumps({"written": stats.written}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
