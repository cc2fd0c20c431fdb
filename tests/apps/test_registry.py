"""Apps found by name through the ``openel_async.apps`` entry points, run by ``openel-async
run NAME`` and ``demo``, the hooks of the app interface, and docs/apps.md's examples."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
import structlog

from openel_apps import arm2_square, arm6_pick_place, pan_tilt, twoaxis
from openel_async import ComponentState, VirtualClock
from openel_async.app import (
    AppContext,
    AppHook,
    AppInfo,
    AppUnavailable,
    DemoOptions,
    discover_apps,
    find_app,
    run_app,
)
from openel_async.cli import main
from openel_async.component import HALComponent
from openel_async.timer import EventTimer

ROOT = Path(__file__).resolve().parents[2]
APPS_DOC = ROOT / "docs" / "apps.md"


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    yield
    structlog.reset_defaults()


def _python_blocks(markdown: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```$", markdown.read_text(), flags=re.M | re.S)


def test_every_app_is_registered_with_its_app_info() -> None:
    entries = {e.name: e for e in discover_apps()}
    assert entries["arm2"].info is arm2_square.APP_INFO
    assert entries["arm6"].info is arm6_pick_place.APP_INFO
    assert entries["twoaxis"].info is twoaxis.APP_INFO
    assert entries["pantilt"].info is pan_tilt.APP_INFO
    assert pan_tilt.APP_INFO.profile == ROOT / "apps" / "openel_apps" / "pan_tilt" / "RTC.yaml"
    assert all(e.error is None for e in entries.values())


def test_demo_list_prints_one_line_per_app(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == [e.name for e in discover_apps()]
    assert any(line.startswith("twoaxis  two axes in step") for line in lines)


def test_find_app_names_the_registered_apps() -> None:
    with pytest.raises(LookupError, match=r"no app named 'arm7' \(registered: arm2, arm6, "):
        find_app("arm7")


def test_run_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "twoaxis", "--virtual", "--duration", "1", "--no-live"]) == 0
    out = capsys.readouterr().out
    assert "summary (simulated devices, openel_sim)" in out
    assert "timer ticks        100 (missed 0)" in out
    assert "sensor faults      0" in out
    assert main(["run", "pantilt", "--virtual", "--duration", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "cycles             20" in out
    assert re.search(r"final positions    pan [+-]\d\.\d{4} rad, tilt [+-]\d\.\d{4} rad", out)
    assert main(["run", "twoaxis", "--period-ms", "0"]) == 2
    assert "openel-async run twoaxis: error: --period-ms 0: from 0.1 to 1000 ms" in (
        capsys.readouterr().err
    )
    assert main(["run", "nosuchapp"]) == 2
    assert "no app named 'nosuchapp'" in capsys.readouterr().err


async def test_the_pan_tilt_axes_have_the_names_the_app_gave() -> None:
    """Not both ``HalMotorOpenELSimMotor`` (issue 21 point 7)."""
    from openel_apps.pan_tilt.pan_tilt import PanTilt

    clock = VirtualClock()
    component = PanTilt("head", clock=clock)
    await component.on_initialize()
    try:
        assert component.pan is not None and component.tilt is not None
        assert (component.pan.device_name, component.tilt.device_name) == ("pan", "tilt")
    finally:
        await component.on_finalize()


def test_run_reports_an_app_that_cannot_load_what_it_needs(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "openel_mujoco", None)
    assert main(["run", "arm2", "--no-live"]) == 1
    err = capsys.readouterr().err
    assert "openel-async run: arm2: MuJoCo is unavailable: ModuleNotFoundError" in err


def test_demo_runs_an_app_without_demo_options_only_plain(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["demo", "--app", "pantilt", "--duration", "1"]) == 2
    assert "app 'pantilt' takes no demo options" in capsys.readouterr().err


class Recorder(AppHook):
    """Everything a hook is told, in order."""

    def __init__(self) -> None:
        self.events: list[str] = []

    async def __aenter__(self) -> Recorder:
        self.events.append("enter")
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.events.append("exit")

    def clock_set(self, ctx: AppContext, clock: object) -> None:
        self.events.append(f"clock {type(clock).__name__}")

    def component_added(self, ctx: AppContext, component: HALComponent) -> None:
        assert component.state is ComponentState.INITIALIZING  # before the app enters it
        self.events.append(component.device_name)

    def timer_added(self, ctx: AppContext, timer: EventTimer) -> None:
        assert timer.stats.ticks == 0  # before it starts
        self.events.append(f"timer {timer.name}")


def test_hooks_see_the_clock_components_and_timers_of_an_app() -> None:
    hook = Recorder()
    argv = ["--virtual", "--duration", "0.3", "--no-live"]
    assert run_app(twoaxis.APP_INFO, argv, prog="t", hooks=[hook]) == 0
    assert hook.events == [
        "enter",
        "clock VirtualClock",
        "MOTOR_1",
        "MOTOR_2",
        "ENCODER_1",
        "TEMP_2",
        "timer sync",
        "exit",
    ]


def test_hooks_see_the_arm_apps_components(tmp_path: Path) -> None:
    hook = Recorder()
    argv = ["--virtual", "--no-live", "--out", str(tmp_path), "--duration", "4"]
    assert run_app(arm2_square.APP_INFO, argv, prog="t", hooks=[hook]) == 0
    assert hook.events == [  # the names the app gave (the model's), not class names
        "enter",
        "clock LockstepClock",
        "shoulder",
        "elbow",
        "tip_pos",  # the rig's components in file order, then its timer
        "timer arm2-sync",
        "exit",
    ]


APPS_WITH_DEMO_OPTIONS = [arm2_square, arm6_pick_place, twoaxis]


@pytest.mark.parametrize("app", APPS_WITH_DEMO_OPTIONS, ids=lambda m: m.APP_INFO.name)
def test_the_demo_and_the_app_agree_on_defaults(app: ModuleType) -> None:
    """Issue 21 point 4: ``openel-async demo`` without options runs the app exactly as
    ``openel-async run NAME`` without options (duration, period, pacing, outputs)."""
    info = app.APP_INFO
    assert info.demo_args is not None
    parser = app.build_parser("t")
    assert parser.parse_args(info.demo_args(DemoOptions())) == parser.parse_args([])
    # Real time by default everywhere; --virtual and --realtime are the same two flags.
    defaults = parser.parse_args([])
    assert (defaults.virtual, defaults.realtime) == (False, False)
    assert parser.parse_args(info.demo_args(DemoOptions(virtual=True))).virtual
    with pytest.raises(SystemExit):
        parser.parse_args(["--virtual", "--realtime"])


@pytest.mark.parametrize("app", APPS_WITH_DEMO_OPTIONS, ids=lambda m: m.APP_INFO.name)
def test_every_app_help_reads_as_sentences(app: ModuleType) -> None:
    """One sentence per option, no reStructuredText backticks (issue 21 points 4 and 7)."""
    parser = app.build_parser("t")
    assert "``" not in parser.format_help()
    for action in parser._actions:
        if action.help and action.dest != "help":
            sentence = action.help.strip()
            assert sentence[0].isupper() and sentence.endswith("."), sentence
            assert ". " not in sentence, sentence


def test_an_app_unavailable_is_raised_to_the_caller() -> None:
    async def needs_hardware(ctx: AppContext) -> int:
        raise AppUnavailable("a robot", "no robot on this desk")

    info = AppInfo("hw", "needs a robot", main=needs_hardware)
    with pytest.raises(AppUnavailable, match="a robot is unavailable: no robot on this desk"):
        run_app(info, [], prog="t")
    with pytest.raises(ValueError, match="exactly one of main and profile"):
        AppInfo("both", "x", main=needs_hardware, profile=Path("RTC.yaml"))
    with pytest.raises(ValueError, match="exactly one of main and profile"):
        AppInfo("none", "x")


def test_context_registration_returns_what_it_registers() -> None:
    ctx = AppContext(["--x"], prog="p")
    clock = VirtualClock()
    assert ctx.use_clock(clock) is clock and ctx.clock is clock
    timer = EventTimer(5, clock=clock)
    assert ctx.add_timer(timer) is timer and ctx.timers == [timer]
    assert ctx.argv == ["--x"] and ctx.components == []


# -- docs/apps.md ---------------------------------------------------------------------------------


def test_the_documented_app_runs_by_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    app = next(b for b in _python_blocks(APPS_DOC) if "APP_INFO = AppInfo(" in b)
    path = tmp_path / "hello_axis.py"
    path.write_text(app)
    assert main(["run", str(path), "--target", "0.5"]) == 0
    out = capsys.readouterr().out
    assert f"openel-async run {path}: back at +0.000 rad after " in out
    assert main(["run", str(path), "--target", "x"]) == 2  # argparse refuses


def test_the_documented_hook_runs() -> None:
    block = next(b for b in _python_blocks(APPS_DOC) if "class Census(AppHook)" in b)
    namespace: dict[str, object] = {"__name__": "docs_apps_census"}
    exec(compile(block, "docs/apps.md", "exec"), namespace)
    census = namespace["census"]
    assert isinstance(census, AppHook)


def test_an_apps_parser_answers_help_and_mistakes_before_the_loop_starts(
    capsys: pytest.CaptureFixture[str],
) -> None:
    import argparse

    started: list[str] = []

    async def app_main(ctx: AppContext) -> int:
        started.append("main")
        return 0

    def parser(prog: str) -> argparse.ArgumentParser:
        built = argparse.ArgumentParser(prog=prog)
        built.add_argument("--speed", type=float, default=1.0)
        return built

    info = AppInfo(name="parsed", description="-", main=app_main, parser=parser)
    assert run_app(info, ["--help"], prog="openel-async run parsed") == 0
    assert "usage: openel-async run parsed [-h] [--speed SPEED]" in capsys.readouterr().out
    assert run_app(info, ["--speed", "fast"], prog="openel-async run parsed") == 2
    assert "argument --speed: invalid float value: 'fast'" in capsys.readouterr().err
    assert started == []  # neither reached main (nor an event loop)
    assert run_app(info, ["--speed", "2"], prog="openel-async run parsed") == 0
    assert started == ["main"]
    for app in (twoaxis, arm2_square, arm6_pick_place):
        assert app.APP_INFO.parser is app.build_parser
