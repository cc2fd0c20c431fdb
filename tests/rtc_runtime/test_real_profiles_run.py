"""The real profiles of tests/rtc/data/real run, each with a small Python implementation
written next to it (the originals are C++/Java components); those whose execution type is
ExtTrigExecutionContext (ConsoleOut, RTCBuilder's TestComp) run a few ticks (issue 21,
point 17)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from openel_async import VirtualClock
from openel_async.rtc import ExecutionKind, LifeCycleState
from openel_async.rtc.configuration import ConfigurationError
from openel_async.rtc.profile import ProfileError, load_profile
from openel_async.rtc.runner import (
    execution_spec,
    load_implementation,
    run_profile,
    run_profile_cli,
    ticks,
)
from openel_async.rtc.system import SystemFileError, load_system, prepare_system

REAL = Path(__file__).parents[1] / "rtc" / "data" / "real"
PROFILES = sorted(p for p in REAL.iterdir() if p.suffix in (".xml", ".yaml"))
EXT_TRIG = {"ConsoleOut.RTC.xml", "TestComp.RTC.xml"}

IMPLEMENTATION = """
from openel_async.rtc import CallbackResult, RTObject


class {name}(RTObject):
    executed = 0

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        self.executed += 1
        return None

    def report(self) -> dict[str, str]:
        return {{"executed": str(self.executed)}}
"""


def _snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.name)
async def test_real_profiles_run(path: Path, tmp_path: Path, virtual_clock: VirtualClock) -> None:
    profile = load_profile(path)
    name = profile.basic_info.name
    copy = tmp_path / f"RTC{path.suffix}"
    shutil.copy(path, copy)
    (tmp_path / f"{_snake(name)}.py").write_text(IMPLEMENTATION.format(name=name))
    if path.name == "RtcSampleVer02.xml":
        # Its own default breaks its own constraint (see the README): one clear error.
        with pytest.raises(ConfigurationError, match="parameter 'config2': value 'Sample'"):
            await run_profile(copy, duration_s=0.05, clock=virtual_clock, handle_signals=False)
        return
    if path.name in EXT_TRIG:
        # Ticked on demand: a minute of simulated time runs no cycle; 3 ticks run 3.
        summary = await run_profile(copy, duration_s=60, clock=virtual_clock, handle_signals=False)
        assert (summary.cycles, summary.ext_trig) == (0, True)
        summary = await run_profile(
            copy, clock=virtual_clock, handle_signals=False, ticker=ticks(3)
        )
        assert summary.cycles == 3
        assert summary.report == {"executed": "3"}
        assert summary.final_state is LifeCycleState.ACTIVE
        assert "EXT_TRIG (one cycle per tick, nominal 1000 Hz)" in "\n".join(summary.lines())
        return
    summary = await run_profile(copy, duration_s=0.05, clock=virtual_clock, handle_signals=False)
    assert summary.rate_hz == profile.basic_info.execution_rate == 1000.0
    assert summary.final_state is LifeCycleState.ACTIVE
    assert 45 <= summary.cycles <= 50


def _script(*argv: str, stdin: str = "") -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "openel_async.cli", *argv],
        input=stdin,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


@pytest.mark.parametrize("name", sorted(EXT_TRIG))
def test_ext_trig_profiles_name_their_context(name: str) -> None:
    spec = execution_spec(load_profile(REAL / name))
    assert spec.ext_trig and spec.kind is ExecutionKind.PERIODIC and spec.rate_hz == 1000.0


def test_consoleout_runs_with_the_console_script(tmp_path: Path) -> None:
    copy = tmp_path / "RTC.xml"
    shutil.copy(REAL / "ConsoleOut.RTC.xml", copy)
    # The profile names no Python implementation and none exists: one clear line.
    done = _script("run", str(copy), "--ticks", "3")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == (
        f"openel-async run: {copy}: rtcProfile.basicInfo.name: no module 'console_out': "
        f"neither {tmp_path / 'console_out.py'} nor an importable module of that name (the "
        "profile describes a C++ component; openel-async runs a Python implementation: write "
        "the class ConsoleOut there, or name one with an 'implementation' parameter)"
    )
    (tmp_path / "console_out.py").write_text(IMPLEMENTATION.format(name="ConsoleOut"))
    # One tick per line of standard input (a number N: N ticks); its end ends the run.
    done = _script("run", str(copy), stdin="\n4\n\n")
    assert done.returncode == 0, done.stderr
    assert "context            EXT_TRIG (one cycle per tick, nominal 1000 Hz)" in done.stdout
    assert "cycles             6 (overruns 0" in done.stdout
    assert "executed           6" in done.stdout


def test_consoleout_ticked_from_a_terminal(tmp_path: Path) -> None:
    # A person at a terminal: told how to tick, Enter ticks once, "2" Enter twice, Ctrl-D
    # ends the run.
    copy = _consoleout(tmp_path)
    master, slave = os.openpty()  # canonical mode: one line per read, Ctrl-D is end of file
    try:
        with subprocess.Popen(
            [sys.executable, "-m", "openel_async.cli", "run", str(copy)],
            stdin=slave,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        ) as process:
            os.write(master, b"\n2\n\x04")
            out, err = process.communicate(timeout=60)
    finally:
        os.close(master)
        os.close(slave)
    assert process.returncode == 0, err
    assert (
        "openel-async run: ExtTrigExecutionContext: Enter ticks once, a number N then Enter "
        "ticks N times, Ctrl-D ends the run" in err
    )
    assert "executed           3" in out


def _consoleout(tmp_path: Path) -> Path:
    copy = tmp_path / "RTC.xml"
    shutil.copy(REAL / "ConsoleOut.RTC.xml", copy)
    (tmp_path / "console_out.py").write_text(IMPLEMENTATION.format(name="ConsoleOut"))
    return copy


def test_ticks_and_tick_rate_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    copy = _consoleout(tmp_path)
    assert run_profile_cli(copy, ["--ticks", "3", "--virtual"]) == 0
    out = capsys.readouterr().out
    assert "cycles             3 (overruns 0" in out and "executed           3" in out
    assert run_profile_cli(copy, ["--ticks", "4", "--tick-rate", "10", "--virtual"]) == 0
    out = capsys.readouterr().out
    assert "duration           0.300 s" in out  # ticks at 0, 0.1, 0.2 and 0.3 s
    assert "executed           4" in out
    assert run_profile_cli(copy, ["--tick-rate", "10", "--duration", "1", "--virtual"]) == 0
    assert "executed           10" in capsys.readouterr().out  # 0.0 .. 0.9 s


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--virtual"], "--virtual needs --duration (simulated time never ends); or --ticks N"),
        (["--ticks", "-1"], "--ticks must be a number of ticks from 0 to 1,000,000"),
        (["--ticks", "2", "--tick-rate", "0"], "--tick-rate must be a number of Hz"),
        (
            ["--tick-rate", "10000", "--duration", "1000", "--virtual"],
            "--tick-rate 10000 Hz for --duration 1000 s is 1e+07 ticks",
        ),
    ],
)
def test_bad_tick_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    assert run_profile_cli(_consoleout(tmp_path), argv) == 2
    assert message in capsys.readouterr().err


def test_ticks_of_a_periodic_profile_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "RTC.xml"
    shutil.copy(REAL / "ConsoleIn.RTC.xml", copy)
    (tmp_path / "console_in.py").write_text(IMPLEMENTATION.format(name="ConsoleIn"))
    assert run_profile_cli(copy, ["--ticks", "3"]) == 2
    assert (
        "--ticks ticks an ExtTrigExecutionContext; this profile's context is "
        "PERIODIC at 1000 Hz" in capsys.readouterr().err
    )


def test_only_real_disagreements_are_logged(tmp_path: Path) -> None:
    from structlog.testing import capture_logs

    # ConsoleOut's profile says on_initialize, on_activated and on_deactivated are
    # implemented (the C++ class does); OnModeChanged="false" agrees with a class that has
    # no modes (it was reported as a mismatch).
    copy = _consoleout(tmp_path)
    with capture_logs() as logs:
        load_implementation(load_profile(copy), copy)
    mismatches = {e["action"] for e in logs if e["event"] == "profile_action_mismatch"}
    assert mismatches == {"on_initialize", "on_activated", "on_deactivated"}


async def test_a_ticker_for_another_context_is_refused(
    tmp_path: Path, virtual_clock: VirtualClock
) -> None:
    copy = tmp_path / "RTC.xml"
    shutil.copy(REAL / "ConsoleIn.RTC.xml", copy)
    (tmp_path / "console_in.py").write_text(IMPLEMENTATION.format(name="ConsoleIn"))
    with pytest.raises(ValueError, match="ticker: the profile's context is PERIODIC"):
        await run_profile(copy, clock=virtual_clock, handle_signals=False, ticker=ticks(1))
    with pytest.raises(ValueError, match="count"):
        ticks(-1)
    with pytest.raises(ValueError, match="rate_hz"):
        ticks(1, rate_hz=0)


def test_an_ext_trig_component_in_a_system_needs_a_context(tmp_path: Path) -> None:
    shutil.copy(REAL / "ConsoleOut.RTC.xml", tmp_path / "ConsoleOut.xml")
    (tmp_path / "console_out.py").write_text(IMPLEMENTATION.format(name="ConsoleOut"))
    system = tmp_path / "system.yaml"
    system.write_text("system:\n  components:\n    out: {profile: ConsoleOut.xml}\n")
    with pytest.raises(SystemFileError, match=r"system\.components\.out\.context: .*ticks nothing"):
        prepare_system(load_system(system), clock=VirtualClock())
    system.write_text(
        "system:\n  components:\n    out:\n      profile: ConsoleOut.xml\n"
        "      context: {type: periodic, rate: 100}\n"
    )
    prepared = prepare_system(load_system(system), clock=VirtualClock())
    assert prepared.components[0].execution.kind is ExecutionKind.PERIODIC


def test_an_unknown_execution_type_is_still_refused_by_run(tmp_path: Path) -> None:
    text = (REAL / "ConsoleOut.RTC.xml").read_text()
    copy = tmp_path / "RTC.xml"
    copy.write_text(text.replace("ExtTrigExecutionContext", "OpenHRPExecutionContext"))
    with pytest.raises(ProfileError, match="unsupported execution type 'OpenHRPExecutionContext'"):
        execution_spec(load_profile(copy))
