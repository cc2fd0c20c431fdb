"""``--record`` through the real console script: a signal to the process group (Ctrl-C in a
terminal reaches the app and its writer process alike) ends the run with a complete file that
the summary names, a killed app leaves a complete file and no traceback of its writer, a run
refused before it ran leaves no file, and an unwritable path is refused before anything runs.

Each run (a small app streaming commands until stopped) is signalled once it printed that it
runs (its writer is ready: it starts before the app), and read to the end of its output: the
writer process inherits the output pipe, so its end comes when the writer has ended too."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

TIMEOUT_S = 60.0


READY = "looper running"
"""What the app below prints once it runs: its writer process is ready (it starts before the
app), its components are Active and a timer streams commands."""

LOOPER = """
import anyio
from openel_async import Actuator, EventTimer, MonotonicClock
from openel_async.app import AppContext, AppInfo
from openel_sim import SimMotor


async def main(ctx: AppContext) -> int:
    clock = ctx.use_clock(MonotonicClock())
    axis = ctx.add_component(Actuator(SimMotor(), device_name="AXIS", clock=clock))
    timer = ctx.add_timer(EventTimer(10, clock=clock, name="loop"))
    async with axis, timer:
        timer.add_observer(lambda t: axis.set_value_nowait(0.1 * (t.ticks_delivered % 5)))
        timer.start_timer()
        await axis.set_value(0.5)
        print("looper running", flush=True)
        await anyio.sleep_forever()  # until a signal stops it
    return 0


APP_INFO = AppInfo("looper", "streams commands until stopped", main=main)
"""


def _looper(tmp_path: Path) -> Path:
    app = tmp_path / "looper.py"
    app.write_text(LOOPER)
    return app


def _start(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,  # a process group of its own, as a terminal's job
    )


def _until_ready(process: subprocess.Popen[str]) -> list[str]:
    """The lines up to and including :data:`READY`."""
    assert process.stdout is not None
    lines = []
    for line in process.stdout:
        lines.append(line)
        if READY in line:
            return lines
    process.kill()
    pytest.fail(f"no line {READY!r}:\n{''.join(lines)}")


def _finish(process: subprocess.Popen[str], lines: list[str]) -> tuple[int, str]:
    """Read the output to its end (the app's and its writer's), then the exit status."""
    assert process.stdout is not None
    lines += process.stdout.readlines()
    return process.wait(timeout=TIMEOUT_S), "".join(lines)


def _complete_messages(path: Path) -> int:
    """The messages of the MCAP file ``path`` read with the ``mcap`` package, which requires
    its summary and footer (a complete file)."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        count = sum(1 for _ in reader.iter_messages())
        assert count == summary.statistics.message_count
        stats = {m.name: m.metadata for m in reader.iter_metadata()}
    assert "openel_async.recorder" in stats  # the writer closed it: its final statistics
    return count


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_to_the_process_group_leaves_a_complete_recording_in_the_summary(
    tmp_path: Path, signum: signal.Signals
) -> None:
    path = tmp_path / "run.mcap"
    process = _start(["run", "--record", str(path), str(_looper(tmp_path))], tmp_path)
    lines = _until_ready(process)
    os.killpg(process.pid, signum)  # the app and its writer process, as Ctrl-C does
    code, out = _finish(process, lines)
    assert code == 128 + signum, out
    assert "Traceback" not in out and "KeyboardInterrupt" not in out, out
    assert "files              none written" not in out
    messages = _complete_messages(path)
    assert f"file written       {path} ({messages} messages, 0 dropped)" in out, out


def test_a_killed_app_leaves_a_complete_recording_and_no_writer_traceback(
    tmp_path: Path,
) -> None:
    path = tmp_path / "killed.mcap"
    process = _start(["run", "--record", str(path), str(_looper(tmp_path))], tmp_path)
    lines = _until_ready(process)
    os.kill(process.pid, signal.SIGKILL)  # the app only: its writer sees its input end
    code, out = _finish(process, lines)  # its end: the writer has exited too
    assert code == -signal.SIGKILL
    assert "Traceback" not in out and "BrokenPipeError" not in out, out
    _complete_messages(path)  # complete: summary, footer, the writer's statistics (what the
    # app had handed over before it was killed: how much depends on when it died)


APP = """
import sys
from openel_async import Actuator, VirtualClock
from openel_async.app import AppContext, AppInfo
from openel_sim import SimMotor


async def main(ctx: AppContext) -> int:
    if ctx.argv != ["--go"]:  # refused for its options, before anything runs
        print(f"{ctx.prog}: bad options {ctx.argv}", file=sys.stderr)
        return 2
    clock = ctx.use_clock(VirtualClock())
    async with ctx.add_component(Actuator(SimMotor(), device_name="AXIS", clock=clock)):
        pass
    print("ran")
    return 0


APP_INFO = AppInfo("refuser", "refuses what is not --go", main=main)
"""


def test_a_run_refused_before_it_ran_leaves_no_recording(tmp_path: Path) -> None:
    app = tmp_path / "refuser.py"
    app.write_text(APP)
    path = tmp_path / "refused.mcap"
    process = _start(["run", "--record", str(path), str(app), "--bogus"], tmp_path)
    code, out = _finish(process, [])
    assert code == 2, out
    assert "bad options" in out
    assert not path.exists(), f"a refused run left {path}"
    assert "recording" not in out
    process = _start(["run", "--record", str(path), str(app), "--go"], tmp_path)
    code, out = _finish(process, [])
    assert code == 0, out
    assert f"  recording          {path} ({_complete_messages(path)} messages, 0 dropped)" in out


def test_an_unwritable_record_path_is_named_before_anything_runs(tmp_path: Path) -> None:
    target = tmp_path / "no-such-dir" / "x.mcap"
    process = _start(["demo", "--bus", "sim", "--record", str(target)], tmp_path)
    code, out = _finish(process, [])
    assert code == 2, out
    assert f"openel-async demo: --record: {target}: no such directory" in out
    assert "state_changed" not in out and "summary" not in out  # nothing ran


def test_a_directory_as_record_path_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from openel_async.cli import main

    assert main(["demo", "--bus", "sim", "--record", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    assert f"openel-async demo: --record: {tmp_path}: is a directory" in captured.err
    assert "summary" not in captured.out


def test_a_port_in_use_leaves_no_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--record with --foxglove on a port in use: refused before anything runs, and the
    MCAP file the writer had opened first is not left behind."""
    import socket

    from openel_async.cli import main

    path = tmp_path / "x.mcap"
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        args = ["demo", "--bus", "sim", "--record", str(path), "--foxglove"]
        assert main([*args, "--foxglove-port", str(port)]) == 2
    assert "--record/--foxglove: cannot start" in capsys.readouterr().err
    assert not path.exists()


@pytest.mark.skipif(not hasattr(os, "login_tty"), reason="a pseudo-terminal (Unix)")
def test_ctrl_c_in_a_terminal_leaves_a_complete_recording(tmp_path: Path) -> None:
    """Ctrl-C typed in a terminal (a pseudo-terminal here: the line discipline sends SIGINT
    to the foreground process group, the app and its writer): no traceback of the writer,
    a complete file, named by the summary."""
    import pty
    import select

    path = tmp_path / "tty.mcap"
    master, slave = pty.openpty()
    process = subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", "run", "--record", str(path),
         str(_looper(tmp_path))],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        cwd=tmp_path,
        preexec_fn=lambda: os.login_tty(slave),  # a session whose terminal it is
    )  # fmt: skip
    os.close(slave)
    out = b""

    def read() -> bytes:
        if not select.select([master], [], [], TIMEOUT_S)[0]:
            process.kill()
            pytest.fail(f"no output within {TIMEOUT_S} s:\n{out.decode(errors='replace')}")
        try:
            return os.read(master, 4096)
        except OSError:  # EIO: every process of the terminal has ended
            return b""

    try:
        while READY.encode() not in out:
            chunk = read()
            assert chunk, out.decode(errors="replace")
            out += chunk
        os.write(master, b"\x03")  # Ctrl-C
        while chunk := read():
            out += chunk
    finally:
        os.close(master)
    code = process.wait(timeout=TIMEOUT_S)
    text = out.decode(errors="replace")
    assert code == 130, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    messages = _complete_messages(path)
    assert f"file written       {path} ({messages} messages, 0 dropped)" in text, text


def test_the_writer_process_is_quiet_at_the_cli_default_level(tmp_path: Path) -> None:
    """The live view's address is said once, by the command; the writer process shares the
    terminal and logs only warnings and errors (it printed foxglove_server_started too)."""
    done = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "run", "twoaxis", "--virtual",
         "--duration", "0.2", "--no-live", "--foxglove", "--foxglove-port", "0",
         "--record", str(tmp_path / "x.mcap")],
        capture_output=True, text=True, timeout=TIMEOUT_S, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Foxglove live view on ws://127.0.0.1:" in done.stdout
    assert "foxglove_server_started" not in done.stdout + done.stderr
    assert done.stderr == ""
