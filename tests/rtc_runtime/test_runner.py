"""The profile runner (``openel-async run RTC.yaml``) on the shipped app, and bad
profiles giving clear errors."""

from __future__ import annotations

import argparse
import copy
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml

from openel_async import VirtualClock
from openel_async.cli import profile_cmd
from openel_async.rtc import ExecutionKind, LifeCycleState
from openel_async.rtc.configuration import ConfigurationError
from openel_async.rtc.profile import ProfileError, load_profile, save_profile
from openel_async.rtc.runner import (
    execution_spec,
    load_implementation,
    run_profile,
    run_profile_cli,
)

APP_DIR = Path(__file__).resolve().parents[2] / "apps" / "pan_tilt"
APP = APP_DIR / "RTC.yaml"


def app_document() -> dict[str, Any]:
    data = yaml.safe_load(APP.read_text())
    assert isinstance(data, dict)
    return data


def write_profile(directory: Path, data: dict[str, Any], name: str = "RTC.yaml") -> Path:
    path = directory / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def with_app(directory: Path, data: dict[str, Any] | None = None) -> Path:
    shutil.copy(APP_DIR / "pan_tilt.py", directory / "pan_tilt.py")
    return write_profile(directory, app_document() if data is None else data)


def cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    profile_cmd.add_parser(parser.add_subparsers(dest="command"))
    return profile_cmd.run(parser.parse_args(argv))


# -- the shipped app -------------------------------------------------------------------


def test_run_the_app_on_the_virtual_clock(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_profile_cli(APP, ["--virtual", "--duration", "5"]) == 0
    out = capsys.readouterr().out
    assert "cycles             500 (overruns 0, skipped 0, periods missed 0)" in out
    assert "context            PERIODIC at 100 Hz" in out
    assert "state at the end   ACTIVE" in out
    # scan 0-2 s (200 cycles), hold 2-4 s, scan 4-5 s (100 cycles): two mode changes
    assert "mode changes       2" in out
    assert "setpoints          600" in out
    assert "mode at the end    scan" in out


async def test_run_profile_summary(virtual_clock: VirtualClock) -> None:
    summary = await run_profile(
        APP, duration_s=1.0, clock=virtual_clock, handle_signals=False, rate_hz=200
    )
    assert summary.kind is ExecutionKind.PERIODIC
    assert summary.rate_hz == 200
    assert summary.cycles == 200
    assert summary.duration_s == 1.0
    assert summary.final_state is LifeCycleState.ACTIVE
    assert summary.report["setpoints"] == 400
    assert summary.mode == "scan"
    assert summary.profile_id == "RTC:OpenEL:Demo:PanTilt:1.0.0"


async def test_configuration_from_the_command_line(virtual_clock: VirtualClock) -> None:
    summary = await run_profile(
        APP,
        duration_s=1.0,
        clock=virtual_clock,
        handle_signals=False,
        settings={"start_mode": "hold", "mode_period": "0"},
    )
    assert summary.mode == "hold"
    assert summary.report["setpoints"] == 0
    assert summary.report["final positions"] == "pan +0.0000 rad, tilt +0.0000 rad"


async def test_the_xml_form_runs_the_same(virtual_clock: VirtualClock, tmp_path: Path) -> None:
    with_app(tmp_path)
    xml = tmp_path / "RTC.xml"
    save_profile(load_profile(APP), xml)
    summary = await run_profile(xml, duration_s=0.5, clock=virtual_clock, handle_signals=False)
    assert summary.cycles == 50
    assert summary.report["setpoints"] == 100


def test_cli_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert run_profile_cli(APP, ["--virtual"]) == 2
    assert "--virtual needs --duration" in capsys.readouterr().err
    assert run_profile_cli(APP, ["--duration", "-1"]) == 2
    assert run_profile_cli(APP, ["--bogus"]) == 2
    assert run_profile_cli(APP, ["--set", "amplitude"]) == 2
    assert "expected NAME=VALUE" in capsys.readouterr().err
    assert run_profile_cli(APP, ["--virtual", "--duration", "1", "--set", "amplitude=3"]) == 2
    err = capsys.readouterr().err
    assert "parameter 'amplitude'" in err and "0<=x<=1.5" in err
    assert run_profile_cli(APP, ["--virtual", "--duration", "1", "--set", "speed=3"]) == 2
    assert "unknown parameter 'speed'" in capsys.readouterr().err
    assert run_profile_cli(tmp_path / "missing.yaml", ["--virtual", "--duration", "1"]) == 2
    assert "no such file" in capsys.readouterr().err
    assert run_profile_cli(APP, ["--virtual", "--duration", "1", "--rate", "0"]) == 2
    assert "--rate: the rate must be" in capsys.readouterr().err


# -- malformed profiles ------------------------------------------------------------------


def _edit(path: tuple[str, ...], value: object) -> dict[str, Any]:
    data = copy.deepcopy(app_document())
    node = data["rtcProfile"]
    for key in path[:-1]:
        node = node[key]
    if value is None:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


def _implementation(value: str) -> dict[str, Any]:
    return _edit(("parameters",), [{"name": "implementation", "defaultValue": value}])


BAD_PROFILES: dict[str, tuple[dict[str, Any], str]] = {
    "missing name": (
        _edit(("basicInfo", "name"), None),
        "rtcProfile.basicInfo.name: required field missing",
    ),
    "unknown execution type": (
        _edit(("basicInfo", "executionType"), "RealTimeExecutionContext"),
        "rtcProfile.basicInfo.executionType: unsupported execution type 'RealTimeExecutionContext'",
    ),
    "zero rate": (
        _edit(("basicInfo", "executionRate"), 0.0),
        "rtcProfile.basicInfo.executionRate: the rate must be a number of Hz, 1e-06 <= rate <= 10000, got 0.0",
    ),
    "bad rate parameter": (
        _edit(
            ("parameters",),
            [
                {"name": "implementation", "defaultValue": "pan_tilt:PanTilt"},
                {"name": "exec_ctxt.periodic.rate", "defaultValue": "fast"},
            ],
        )
        | {"rtcProfile": _edit(("basicInfo", "executionRate"), None)["rtcProfile"]},
        "",  # replaced below
    ),
    "default violates its constraint": (
        _edit(
            ("configurationSet", "configuration"),
            [{"name": "amplitude", "type": "double", "defaultValue": "2", "constraint": "x"}],
        ),
        "",
    ),
    "no such module": (
        _implementation("no_such_module:Thing"),
        "rtcProfile.parameters[0].defaultValue: no module 'no_such_module'",
    ),
    "no such class": (
        _implementation("pan_tilt:Tilt"),
        "rtcProfile.parameters[0].defaultValue: module 'pan_tilt' has no class 'Tilt'",
    ),
    "not a component": (
        _implementation("pan_tilt:Actuator"),
        "rtcProfile.parameters[0].defaultValue: pan_tilt:Actuator is not an RTObject subclass",
    ),
    "empty implementation": (
        _implementation(" "),
        "rtcProfile.parameters[0].defaultValue: expected 'module:Class'",
    ),
    "kind needs modes": (
        _implementation("openel_async.rtc.rtobject:RTObject"),
        "rtcProfile.basicInfo.componentKind: DataFlowMultiModeComponent needs a MultiModeObject",
    ),
}


def _bad_rate_parameter() -> dict[str, Any]:
    data = _edit(
        ("parameters",),
        [
            {"name": "implementation", "defaultValue": "pan_tilt:PanTilt"},
            {"name": "exec_ctxt.periodic.rate", "defaultValue": "fast"},
        ],
    )
    del data["rtcProfile"]["basicInfo"]["executionRate"]
    return data


def _bad_default() -> dict[str, Any]:
    data = copy.deepcopy(app_document())
    data["rtcProfile"]["configurationSet"]["configuration"][0]["defaultValue"] = "2"
    return data


BAD_PROFILES["bad rate parameter"] = (
    _bad_rate_parameter(),
    "rtcProfile.parameters[1].defaultValue: exec_ctxt.periodic.rate must be a number, got 'fast'",
)
BAD_PROFILES["default violates its constraint"] = (
    _bad_default(),
    "configuration: default value: parameter 'amplitude': value '2' violates constraint "
    "'0<=x<=1.5'",
)


@pytest.mark.parametrize("case", list(BAD_PROFILES))
def test_malformed_profiles_give_clear_errors(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data, message = BAD_PROFILES[case]
    path = with_app(tmp_path, data)
    assert run_profile_cli(path, ["--virtual", "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"openel-async run: {path}: ")
    assert message in err, err
    # ``profile validate`` says the same (with --implementation for the class checks)
    assert cli(["profile", "validate", str(path), "--implementation"]) == 1
    assert message.removeprefix("configuration: ") in capsys.readouterr().err


def test_garbage_documents(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for name, text, message in (
        ("a.yaml", "rtcProfile: [1, 2", "<document>"),
        ("b.yaml", "- just a list\n", "<document>"),
        ("c.xml", "<notAProfile/>", "<document>"),
        ("d.txt", "rtcProfile: {}", "unknown profile format '.txt'"),
    ):
        path = tmp_path / name
        path.write_text(text)
        assert run_profile_cli(path, ["--virtual", "--duration", "1"]) == 2
        err = capsys.readouterr().err
        assert message in err, err


def test_importing_a_broken_module(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "broken.py").write_text("raise RuntimeError('no hardware here')\n")
    path = write_profile(tmp_path, _implementation("broken:Thing"))
    assert run_profile_cli(path, ["--virtual", "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "importing" in err and "no hardware here" in err


def test_failing_activation_exits_cleanly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "failing.py").write_text(
        "from openel_async.rtc import MultiModeObject, ReturnCode_t\n"
        "events = []\n"
        "class Failing(MultiModeObject):\n"
        "    async def on_activated(self, exec_handle):\n"
        "        return ReturnCode_t.OUT_OF_RESOURCES\n"
        "    async def on_finalize(self):\n"
        "        events.append('finalized')\n"
    )
    path = write_profile(tmp_path, _implementation("failing:Failing"))
    assert run_profile_cli(path, ["--virtual", "--duration", "1"]) == 1
    err = capsys.readouterr().err
    assert "CallbackFailedError (RTC_ERROR)" in err
    assert "on_activated failed with OUT_OF_RESOURCES" in err
    profile = load_profile(path)
    module = load_implementation(profile, path).__module__
    import sys

    assert sys.modules[module].events == ["finalized"]


async def test_implementation_by_name_and_event_driven(
    virtual_clock: VirtualClock, tmp_path: Path
) -> None:
    (tmp_path / "my_sensor.py").write_text(
        "from openel_async.rtc import RTObject\n"
        "class MySensor(RTObject):\n"
        "    executed = 0\n"
        "    async def on_activated(self, exec_handle):\n"
        "        self.get_context(exec_handle).trigger()\n"
        "    async def on_execute(self, exec_handle):\n"
        "        type(self).executed += 1\n"
    )
    data = _edit(("parameters",), None)
    data["rtcProfile"]["basicInfo"].update(
        name="MySensor",
        componentKind="DataFlowComponent",
        executionType="EventDrivenExecutionContext",
    )
    path = write_profile(tmp_path, data, "MySensor.yaml")
    spec = execution_spec(load_profile(path))
    assert (spec.kind, spec.rate_hz) == (ExecutionKind.EVENT_DRIVEN, None)
    summary = await run_profile(path, duration_s=1, clock=virtual_clock, handle_signals=False)
    assert summary.kind is ExecutionKind.EVENT_DRIVEN
    assert summary.cycles == 1  # the one trigger of on_activated
    assert summary.mode is None


async def test_rate_from_the_parameter_or_the_default(tmp_path: Path) -> None:
    data = _edit(("basicInfo", "executionRate"), None)
    spec = execution_spec(load_profile(write_profile(tmp_path, data)))
    assert spec.rate_hz == 1000.0
    data["rtcProfile"]["parameters"].append(
        {"name": "exec_ctxt.periodic.rate", "defaultValue": "250"}
    )
    spec = execution_spec(load_profile(write_profile(tmp_path, data)))
    assert spec.rate_hz == 250.0
    data["rtcProfile"]["basicInfo"]["executionType"] = "PERIODIC"
    assert execution_spec(load_profile(write_profile(tmp_path, data)), 10).rate_hz == 10


async def test_run_profile_checks_its_arguments(virtual_clock: VirtualClock) -> None:
    with pytest.raises(ValueError, match="duration_s"):
        await run_profile(APP, duration_s=0, clock=virtual_clock)
    with pytest.raises(ValueError, match="needs handle_signals"):
        await run_profile(APP, clock=virtual_clock, handle_signals=False)
    with pytest.raises(ConfigurationError):
        await run_profile(
            APP, duration_s=1, clock=virtual_clock, handle_signals=False, settings={"x": "1"}
        )
    with pytest.raises(ProfileError):
        await run_profile(
            APP.with_suffix(".json"), duration_s=1, clock=virtual_clock, handle_signals=False
        )


# -- openel-async profile ... --------------------------------------------------------------


def test_profile_validate_show_convert(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["profile", "validate", str(APP)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"OK: {APP}: RTC:OpenEL:Demo:PanTilt:1.0.0")
    assert "PERIODIC at 100 Hz, 6 configuration parameter(s)" in out
    assert cli(["profile", "validate", str(APP), "--implementation"]) == 0
    assert "implementation PanTilt from" in capsys.readouterr().out
    assert cli(["profile", "show", str(APP)]) == 0
    out = capsys.readouterr().out
    assert "implementation  pan_tilt:PanTilt" in out
    assert "amplitude      double     = 0.5 rad  [0<=x<=1.5]" in out
    assert "on_mode_changed" in out
    xml = tmp_path / "RTC.xml"
    assert cli(["profile", "convert", str(APP), str(xml)]) == 0
    assert load_profile(xml) == load_profile(APP)
    assert cli(["profile", "convert", str(xml)]) == 0  # to stdout, in the other form
    printed = capsys.readouterr().out
    assert printed.startswith("rtcProfile:") or "rtcProfile:" in printed.splitlines()[1]
    assert cli(["profile", "convert", str(APP), "--to", "xml"]) == 0
    assert "<rtc:RtcProfile" in capsys.readouterr().out
    assert cli(["profile", "show", str(tmp_path / "none.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert cli(["profile", "convert", str(APP), str(tmp_path / "out.json")]) == 1
    assert "unknown profile format" in capsys.readouterr().err


def test_profile_command_is_wired_into_the_cli(capsys: pytest.CaptureFixture[str]) -> None:
    from openel_async.cli import main

    assert main(["--log-level", "warning", "profile", "validate", str(APP)]) == 0
    assert capsys.readouterr().out.startswith("OK: ")


async def test_sigint_ends_the_run_cleanly(virtual_clock: VirtualClock) -> None:
    import os
    import signal

    import anyio

    summaries = []

    async def run() -> None:
        summaries.append(await run_profile(APP, clock=virtual_clock))

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await virtual_clock.sleep(1.0)
        os.kill(os.getpid(), signal.SIGINT)
    (summary,) = summaries
    assert summary.duration_s >= 1.0
    assert summary.cycles >= 100
    assert summary.final_state is LifeCycleState.ACTIVE
    assert summary.report["final positions"] != ""


def test_openel_async_run_dispatches_profiles(capsys: pytest.CaptureFixture[str]) -> None:
    from openel_async.cli import main

    argv = ["--log-level", "warning", "run", str(APP), "--virtual", "--duration", "0.5"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "cycles             50 (overruns 0, skipped 0, periods missed 0)" in captured.out
    assert "profile_action_mismatch" not in captured.out + captured.err


def test_profile_and_class_disagreeing_on_actions_is_logged(tmp_path: Path) -> None:
    from structlog.testing import capture_logs

    data = app_document()
    data["rtcProfile"]["actions"]["onExecute"] = {"implemented": False}
    data["rtcProfile"]["actions"]["onReset"] = {"implemented": True}
    path = with_app(tmp_path, data)
    with capture_logs() as logs:
        load_implementation(load_profile(path), path)
    mismatches = {
        (e["action"], e["profile_says"], e["class_overrides"])
        for e in logs
        if e["event"] == "profile_action_mismatch"
    }
    assert mismatches == {("on_execute", False, True), ("on_reset", True, False)}


def test_realtime_and_virtual_are_the_apps_flags(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 21 point 4: a profile run takes --realtime (the default) and --virtual like every
    app; the two exclude each other."""
    assert run_profile_cli(APP, ["--realtime", "--duration", "0.05"]) == 0
    assert "cycles" in capsys.readouterr().out
    assert run_profile_cli(APP, ["--realtime", "--virtual", "--duration", "1"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
