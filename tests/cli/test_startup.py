"""Issue 27 point 2: each command loads what it uses. ``openel-async --help`` lists every
command (the drivers' too) without importing the heavy libraries behind them."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

# (python-can and pyserial are still loaded by the can and serial drivers' contributed
# commands: their packages import their modules at once)
HEAVY = (
    "structlog",
    "mujoco",
    "matplotlib",
    "numpy",
    "zenoh",
    "foxglove",
    "textual",
    "rich",
    "can",  # python-can
    "canopen",
    "serial",  # pyserial
    "msgspec",
    "yaml",
    "anyio",
)


def test_help_imports_none_of_the_heavy_libraries() -> None:
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "openel_async.cli", "--help"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "serve" in done.stdout and "rig" in done.stdout  # a driver's command, the framework's
    imported = set(re.findall(r"^import time:\s+\d+ \|\s+\d+ \| +(\S+)$", done.stderr, re.M))
    assert "openel_async.cli" in imported  # (the output is what this test reads)
    top = {name.split(".")[0] for name in imported}
    assert not top.intersection(HEAVY), sorted(top.intersection(HEAVY))
    assert "importlib.metadata" not in imported  # (openel_async.entrypoints reads them)


def test_an_apps_help_imports_only_what_it_runs_on() -> None:
    """``openel-async run NAME --help`` imports the app (its parser is built in ``main``) but
    neither the rig files' libraries (yaml, msgspec), MuJoCo, numpy nor rich: the apps load
    them when they open a rig or show progress. arm2 is the heaviest (MuJoCo, plots). Nor
    asyncio or ctypes: the framework's clocks, wake-ups and timerfd load them at their first
    wait (anyio, which the app imports, loads its asyncio backend only in ``anyio.run``)."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "openel_async.cli", "run", "arm2", "--help"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "usage: openel-async run arm2" in done.stdout
    imported = set(re.findall(r"^import time:\s+\d+ \|\s+\d+ \| +(\S+)$", done.stderr, re.M))
    assert "openel_apps.arm_rig" in imported  # (the app was loaded)
    top = {name.split(".")[0] for name in imported}
    heavy = (set(HEAVY) - {"anyio"}) | {"asyncio", "ctypes"}  # the app runs on anyio
    assert not top.intersection(heavy), sorted(top.intersection(heavy))
    assert "openel_async.rig" not in imported
    assert {"openel_async.clock", "openel_async.wakeup"} <= imported  # (they were imported)
    assert "importlib.metadata" not in imported


def test_a_profile_apps_help_loads_no_rtc_machinery() -> None:
    """``openel-async run pantilt --help`` (an app run from its RTC Profile) answers from the
    profile runner's parser alone: neither the RTC package, its profile loaders nor yaml and
    msgspec are imported."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "openel_async.cli", "run", "pantilt", "--help"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "--duration" in done.stdout and "--set NAME=VALUE" in done.stdout
    imported = set(re.findall(r"^import time:\s+\d+ \|\s+\d+ \| +(\S+)$", done.stderr, re.M))
    assert "openel_async.run_profile_args" in imported  # (the output is what this test reads)
    top = {name.split(".")[0] for name in imported}
    heavy = set(HEAVY) - {"anyio"}
    assert not top.intersection(heavy), sorted(top.intersection(heavy))
    assert "openel_async.rtc" not in imported


def test_every_module_logs_through_the_lazy_logger() -> None:
    """``structlog.get_logger`` at module level would import structlog (and rich) with the
    module: every module takes ``openel_async.logs.get_logger`` instead."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    offenders = [
        f"{path.relative_to(root)}:{n}"
        for folder in ("src", "drivers", "apps", "examples")
        for path in sorted((root / folder).rglob("*.py"))
        if path.name != "logs.py"
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if "structlog.get_logger(" in line
    ]
    assert offenders == []


def test_devices_lists_every_driver_without_importing_them() -> None:
    """The drivers give their device classes as ``module:Class`` paths: listing them imports
    no device module, and logging (structlog) is configured only if something logs."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "openel_async.cli", "devices"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for line in ("sim ", "mujoco ", "can ", "serial ", "zenoh "):
        assert any(row.startswith(line) for row in done.stdout.splitlines()), line
    assert "openel_mujoco.devices.MujocoJoint" in done.stdout
    assert "openel_can.drive402.Cia402Drive" in done.stdout
    imported = set(re.findall(r"^import time:\s+\d+ \|\s+\d+ \| +(\S+)$", done.stderr, re.M))
    top = {name.split(".")[0] for name in imported}
    assert not top.intersection(HEAVY), sorted(top.intersection(HEAVY))
    assert "openel_sim.motor" not in imported and "openel_can.odrive" not in imported


def test_a_deferred_configuration_applies_at_the_first_log_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from openel_async.cli.logs import configure_logging, reset_logging
    from openel_async.logs import get_logger

    try:
        configure_logging("json", "info", defer=True)
        get_logger("openel_async.test_startup").info("deferred_event", answer=42)
        line = capsys.readouterr().err.strip().splitlines()[-1]
    finally:
        reset_logging()
    import json

    record = json.loads(line)
    assert record["event"] == "deferred_event" and record["answer"] == 42
    assert record["level"] == "info" and "timestamp" in record


@pytest.mark.parametrize(
    ("argv", "command"),
    [
        (["run", "arm2", "--help"], "run"),
        (["-v", "--log-level", "info", "-qv", "--log-format=json", "devices"], "devices"),
        (["--log-level=debug", "-vv", "--quiet", "--verbose", "rig", "check"], "rig"),
        (["--log-level", "run"], None),  # "run" is the level (argparse refuses it)
        (["--help", "run"], None),
        (["--version"], None),
        (["--", "run"], None),
        (["-x", "run"], None),
        ([], None),
    ],
)
def test_the_named_command_is_found_as_argparse_finds_it(
    argv: list[str], command: str | None
) -> None:
    from openel_async.cli import named_command

    assert named_command(argv) == command


def test_a_named_command_parses_as_with_every_commands_parser() -> None:
    """The parser built for one command (SOLO_COMMANDS: nothing contributed to them) holds
    exactly what the whole parser holds for it, and the global options."""
    import argparse

    from openel_async.cli import SOLO_COMMANDS, _build_parser
    from openel_async.cli.options import GLOBAL_FLAGS, GLOBAL_VALUE_OPTIONS, SHORT_GLOBAL_FLAGS

    def shape(parser: argparse.ArgumentParser) -> list[object]:
        out: list[object] = [parser.prog, parser.description]
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                out.append({name: shape(child) for name, child in action.choices.items()})
            else:
                out.append((action.option_strings, action.dest, action.nargs, action.help,
                            action.default, action.choices))  # fmt: skip
        return out

    def commands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return dict(action.choices)

    whole = _build_parser()
    for name in SOLO_COMMANDS:
        alone = _build_parser(name)
        assert list(commands(alone)) == [name]
        assert shape(commands(alone)[name]) == shape(commands(whole)[name]), name
        assert shape(alone)[:-1] == shape(whole)[:-1]  # the top-level options
    argv = ["-v", "--log-level", "info", "run", "--record", "x.mcap", "arm2", "--speed", "2"]
    assert _build_parser("run").parse_args(argv) == whole.parse_args(argv)
    options = {s: a.nargs != 0 for a in whole._actions for s in a.option_strings}
    for own in ("-h", "--help", "--version"):  # (named_command stops at these)
        del options[own]
    assert {s for s, takes in options.items() if takes} == GLOBAL_VALUE_OPTIONS
    assert {s for s, takes in options.items() if not takes} == GLOBAL_FLAGS
    assert {f"-{c}" for c in SHORT_GLOBAL_FLAGS} <= GLOBAL_FLAGS
