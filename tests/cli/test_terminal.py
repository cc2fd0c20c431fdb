"""Progress and log lines on a terminal (issue 21 point 2): a log record never shares a
screen line with the live progress line; the default level shows warnings, not info."""

from __future__ import annotations

import io
import os
import pty
import re
import sys
from collections.abc import Iterator

import pytest
import structlog

from openel_async.app import LiveLine
from openel_async.cli.logs import configure_logging, reset_logging

from .terminal import read_all, run_cli_in_pty, screen, set_size

LOG_RECORD = re.compile(r"\[(debug|info|warning|error)\s*\]")


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    yield
    reset_logging()


def _progress_and_logs_apart(lines: list[str], progress: str) -> tuple[int, int]:
    shown = [line for line in lines if progress in line]
    logged = [line for line in lines if LOG_RECORD.search(line)]
    both = [line for line in shown if LOG_RECORD.search(line)]
    assert both == [], "a log record on the progress line:\n" + "\n".join(both)
    return len(shown), len(logged)


def test_log_records_print_above_the_live_line(monkeypatch: pytest.MonkeyPatch) -> None:
    master, slave = pty.openpty()
    set_size(slave)
    term = io.TextIOWrapper(os.fdopen(slave, "wb", buffering=0), write_through=True)
    monkeypatch.setattr(sys, "stdout", term)
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setenv("COLUMNS", "120")
    configure_logging("console", "warning")
    log = structlog.get_logger("openel_async.test")
    live = LiveLine(term)
    try:
        live.update("progress t=0.1", force=True)
        log.warning("first_warning", device="MOTOR_2")
        live.update("progress t=0.2", force=True)
        log.info("not_shown")
        print("printed by the app")
        log.error("an_error", code=7)
        live.update("progress t=0.3", force=True)
    finally:
        live.finish()
        monkeypatch.undo()
        term.close()
    lines = screen(read_all(master, timeout=1.0).decode())
    os.close(master)
    shown, logged = _progress_and_logs_apart(lines, "progress t=")
    assert logged == 2 and shown == 1, lines
    text = [line for line in lines if line]
    assert "first_warning" in text[0] and text[1] == "printed by the app"
    assert "an_error" in text[2] and text[3] == "progress t=0.3"  # the last line stays
    assert "not_shown" not in "\n".join(lines)


def test_the_demo_on_a_terminal_keeps_logs_off_the_progress_line() -> None:
    # the fault injected halfway logs a warning and an error while the progress line shows
    code, output = run_cli_in_pty(
        "demo", "--bus", "sim", "--virtual", "--duration", "1", "--inject-fault"
    )
    lines = screen(output)
    assert code == 0, "\n".join(lines)
    shown, logged = _progress_and_logs_apart(lines, "ticks=")
    assert shown >= 1 and logged >= 2, "\n".join(lines)
    assert any("demo_injecting_fault" in line for line in lines)
    assert not any(re.search(r"\[info\s*\]", line) for line in lines)  # default: warnings
    assert "summary (simulated devices, openel_sim)" in lines
