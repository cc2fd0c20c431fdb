"""The writer process of the recorder and the live view: it reads the control loop's records
from its stdin, encodes them as JSON messages (msgspec) and logs each once on a channel of a
Foxglove SDK context, whose sinks -- the SDK's MCAP writer (:class:`~.mcap_sink.McapSink`,
Rust, zstd chunks) and/or its WebSocket server (:class:`~.live.FoxgloveSink`) -- write and
publish it.

Running in a process of its own, encoding and writing never compete with the control loop for
the interpreter lock: the application only appends tuples to a list. The parent
(:class:`~.pipeline.Pipeline`) sends frames: a 4-byte little-endian length, then a msgpack
list of entries (:mod:`.records`). When its stdin closes -- the parent finished or was
killed -- the process writes what it received, closes the MCAP file (summary and footer) and
exits. It prints one JSON line when ready (``{"port": N}``: the WebSocket port) and one when
done (``{"written": N, "cpu_s": S}``: the CPU time it spent writing; not printed, and no error
either, when the parent is gone).

It ignores SIGINT and SIGTERM (the parent starts it with
:data:`~.pipeline.WRITER_BOOTSTRAP`, which does that before anything is imported): Ctrl-C in
a terminal and a SIGTERM to the process group reach the parent and its writer alike, and the
parent stops the run, then closes the writer's input, which ends it with a complete file. A
signal must not cut the file first, nor print a ``KeyboardInterrupt`` traceback of the
writer beside the parent's summary.

``python -m openel_async.recording.sink_process [--mcap PATH] [--foxglove HOST:PORT]
[--chunk-size BYTES] [--nice N] [--idle] [--cpu N]``
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import sys
import time
from collections.abc import Callable
from typing import Any, BinaryIO

import foxglove
import msgspec

from .columns import column_messages
from .records import BATCH, CHANNEL, COLUMNS, COMMAND, HEADER, SCHEMAS, STATS, to_message
from .schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, Schema
from .sinks import PipelineStats, Sink

LogCall = Callable[[bytes, int | None, int | None], None]


def ignore_stop_signals() -> None:
    """SIGINT and SIGTERM are the parent's to handle (see the module docstring)."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError, OSError):  # not the main thread
            signal.signal(signum, signal.SIG_IGN)


def say(info: dict[str, Any]) -> bool:
    """Print ``info`` as a JSON line to the parent; False (quietly) when the parent is gone
    (its end of the pipe closed: killed). stdout then goes to /dev/null, so that nothing
    fails again when the interpreter flushes it at exit."""
    try:
        print(json.dumps(info), flush=True)
    except (BrokenPipeError, ValueError, OSError):
        with contextlib.suppress(OSError, ValueError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        return False
    return True


def flush(out: list[tuple[int, LogCall, bytes]]) -> int:
    """Log the messages of ``out`` in log-time order (stable: in order within a time), then
    empty it; how many."""
    out.sort(key=_log_time)
    for log_time, log, data in out:
        log(data, log_time, None)
    n = len(out)
    out.clear()
    return n


def _log_time(item: tuple[int, LogCall, bytes]) -> int:
    return item[0]


def serve(stream: BinaryIO, context: foxglove.Context, schemas: dict[str, Schema]) -> PipelineStats:
    """Log every entry of ``stream`` on ``context``'s channels until it ends (or is cut)."""
    decode = msgspec.msgpack.Decoder().decode
    encode = msgspec.json.Encoder().encode
    keep: list[foxglove.Channel] = []
    logs: dict[int, tuple[LogCall, int]] = {}  # channel id -> (its log call, time offset)
    written = queued = dropped = capacity = 0
    out: list[tuple[int, LogCall, bytes]] = []
    add = out.append
    read = stream.read
    while True:
        header = read(4)
        if len(header) < 4:
            break
        (size,) = HEADER.unpack(header)
        payload = read(size)
        if len(payload) < size:  # the parent died mid-frame
            break
        # A frame's messages are logged in log-time order (stable): a channel's records in
        # a column buffer and in the queue were taken at the same moment but kept apart.
        for entry in decode(payload):
            channel = entry[0]
            if channel >= 0:
                log, offset = logs[channel]
                add((entry[1] + offset, log, encode(to_message(entry))))
            elif channel == COLUMNS:
                for cid, t, message in column_messages(entry):
                    log, offset = logs[cid]
                    add((t + offset, log, encode(message)))
            elif channel == BATCH:  # a bank's commands: one message per component
                _, t, _, request, channels, values = entry
                for cid, value in zip(channels, values, strict=True):
                    log, offset = logs[cid]
                    add((t + offset, log, encode(to_message([cid, t, COMMAND, request, value]))))
            elif channel == CHANNEL:
                written += flush(out)  # the messages before it, then the channel
                _, offset, _, cid, topic, schema_name, metadata = entry
                schema = schemas[schema_name]
                created = foxglove.Channel(
                    topic,
                    schema=foxglove.Schema(
                        name=schema.name, encoding=SCHEMA_ENCODING, data=schema.data
                    ),
                    message_encoding=MESSAGE_ENCODING,
                    context=context,
                    metadata=metadata,
                )
                keep.append(created)
                logs[cid] = (created.base.log, offset)
            elif channel == STATS:
                _, queued, dropped, capacity = entry
        written += flush(out)
    for created in keep:
        created.close()
    return PipelineStats(queued or written, written, dropped, capacity)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="openel_async.recording.sink_process")
    parser.add_argument("--mcap", default=None)
    parser.add_argument("--foxglove", default=None, metavar="HOST:PORT")
    parser.add_argument("--chunk-size", type=int, default=64 * 1024)
    parser.add_argument("--nice", type=int, default=0, help="niceness to add (before any thread)")
    parser.add_argument(
        "--idle", action="store_true", help="the SCHED_IDLE policy (Linux; before any thread)"
    )
    parser.add_argument(
        "--cpu", type=int, default=None, help="the one CPU to run on (before any thread)"
    )
    args = parser.parse_args(argv)
    ignore_stop_signals()
    if args.nice and hasattr(os, "nice"):
        os.nice(args.nice)  # the control loop comes first; this process catches up
    if args.idle and hasattr(os, "SCHED_IDLE"):
        # Runs only on a CPU nothing else wants: it never preempts the control loop, and the
        # scheduler counts its CPU as idle when it places the loop (the parent raises it back
        # to SCHED_OTHER for the final drain).
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    if args.cpu is not None and hasattr(os, "sched_setaffinity"):
        # the SDK's server threads (one per core by default) inherit it: the writer never
        # takes more than one core, whatever its niceness
        os.sched_setaffinity(0, {args.cpu})
    # stdout carries the ready line: the log goes to stderr, warnings and errors only (the
    # parent says where the file and the live view are; this process shares its terminal).
    # (plain logging: the framework's loggers reach it through openel_async._logging when
    # they are first used; structlog is not imported unless something logs)
    logging.basicConfig(stream=sys.stderr, level=logging.WARNING, format="%(name)s: %(message)s")
    context = foxglove.Context()
    sinks: list[Sink] = []
    info: dict[str, Any] = {}
    try:
        if args.mcap is not None:
            from .mcap_sink import McapSink

            sinks.append(McapSink(args.mcap, context=context, chunk_size=args.chunk_size))
        if args.foxglove is not None:
            from .sinks import FoxgloveSink

            host, _, port = args.foxglove.rpartition(":")
            live = FoxgloveSink(host=host, port=int(port), context=context)
            sinks.append(live)
            info["port"] = live.port
    except Exception as exc:
        say({"error": f"{type(exc).__name__}: {exc}"})
        for sink in sinks:
            sink.close(PipelineStats(0, 0, 0, 0))
        return 1
    say(info)  # the parent gone already: its input ends at once, and the file is closed
    cpu = time.process_time()
    stats = serve(sys.stdin.buffer, context, SCHEMAS)
    for sink in sinks:
        sink.close(stats)
    cpu = time.process_time() - cpu
    say({"written": stats.written, "cpu_s": cpu})  # nobody to tell when the parent was killed
    return 0


if __name__ == "__main__":
    sys.exit(main())
