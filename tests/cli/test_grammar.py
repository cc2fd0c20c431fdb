"""One command-line grammar (issue 21 points 4, 5 and 7): global options before or after
the command, --version, shell completion, no hidden option and no reST in any help, tap
options after the app's name, one message and exit status for a missing file."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections.abc import Iterator
from importlib.metadata import version
from pathlib import Path

import pytest

from openel_async.cli import _build_parser, main
from openel_async.cli.logs import reset_logging
from openel_async.cli.options import log_level
from openel_async.recording import read_recording

ROOT = Path(__file__).resolve().parents[2]
RST = re.compile(r"``|:(class|mod|func|meth|data|attr|exc|ref):`")


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    yield
    reset_logging()


def _cli(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
    )  # fmt: skip


def test_the_console_script_names_a_missing_file_and_has_a_version(tmp_path: Path) -> None:
    missing_yaml, missing_xml = tmp_path / "missing.yaml", tmp_path / "missing.xml"
    runs = {
        "version": _cli("--version"),
        "profile": _cli("profile", "validate", str(missing_yaml)),
        "hal4rt": _cli("hal4rt", "validate", str(missing_xml)),
    }
    out = {name: (*proc.communicate(timeout=60), proc.returncode) for name, proc in runs.items()}
    assert out["version"] == (f"openel-async {version('openel-async')}\n", "", 0)
    assert out["profile"] == (
        "",
        f"openel-async profile validate: {missing_yaml}: no such file\n",
        2,
    )
    assert out["hal4rt"] == ("", f"openel-async hal4rt validate: {missing_xml}: no such file\n", 2)


@pytest.mark.parametrize(
    "command",
    [
        "profile validate",
        "profile show",
        "profile convert",
        "hal4rt validate",
        "hal4rt show",
        "hal4rt exec",
        "run",
        "record info",
        "record plot",
        "replay",
        "serve",
    ],
)
@pytest.mark.parametrize("name", ["missing.yaml", "missing.xml", "missing.mcap", "missing.py"])
def test_every_missing_file_is_named_with_exit_status_2(
    command: str, name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / name
    assert main([*command.split(), str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"openel-async {command}: {path}: no such file\n"
    assert captured.out == ""


def test_a_folder_is_not_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["record", "info", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"openel-async record info: {tmp_path}: is a folder, not a file\n"  # fmt: skip


@pytest.mark.parametrize(
    ("argv", "level", "log_format"),
    [
        (["devices"], "warning", "console"),
        (["-v", "devices"], "info", "console"),
        (["devices", "-v"], "info", "console"),
        (["-v", "devices", "--verbose"], "debug", "console"),
        (["devices", "-q"], "error", "console"),
        (["--quiet", "devices"], "error", "console"),
        (["devices", "--log-level", "info", "--log-format", "json"], "info", "json"),
        (["--log-level", "debug", "profile", "-q", "show", "-q", "x.yaml"], "warning", "console"),
        (["--log-format", "json", "hal4rt", "validate", "x.xml", "-vv"], "debug", "json"),
        (["run", "-v", "twoaxis", "-q"], "info", "console"),  # after the name: the app's
    ],
)
def test_global_options_work_before_or_after_the_command(
    argv: list[str], level: str, log_format: str
) -> None:
    args = _build_parser().parse_args(argv)
    assert (log_level(args), args.log_format) == (level, log_format)


def _parsers(
    parser: argparse.ArgumentParser,
) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield parser.prog, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                yield from _parsers(child)


def test_every_help_reads_well() -> None:
    parsers = dict(_parsers(_build_parser()))
    assert {"openel-async demo", "openel-async run", "openel-async serve",
            "openel-async hal4rt exec", "openel-async completion"} <= set(parsers)  # fmt: skip
    for prog, parser in parsers.items():
        text = parser.format_help()
        assert not RST.search(text), f"{prog} --help: reST markup\n{text}"
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue  # each command has its help
            assert action.help and action.help != argparse.SUPPRESS, (prog, action.dest)
        assert "--log-level" in text and "-v, --verbose" in text, prog
    demo = parsers["openel-async demo"].format_help()
    for hidden in ("--foxglove-host HOST", "--foxglove-port PORT", "--realtime"):
        assert (hidden in demo and hidden in parsers["openel-async run"].format_help()) or (
            hidden == "--realtime" and hidden in demo
        )
    duration = demo.split("\n  --duration S", 1)[1].split("\n  --", 1)[0]
    sentences = [line.strip() for line in duration.splitlines()[1:]]
    assert [s.split(":")[0] for s in sentences] == ["arm2", "arm6", "twoaxis"], duration


def test_demo_realtime_is_the_opposite_of_virtual(capsys: pytest.CaptureFixture[str]) -> None:
    parser = _build_parser()
    assert parser.parse_args(["demo"]).virtual is False
    assert parser.parse_args(["demo", "--virtual"]).virtual is True
    assert parser.parse_args(["demo", "--realtime"]).virtual is False
    with pytest.raises(SystemExit) as exit_info:
        parser.parse_args(["demo", "--virtual", "--realtime"])
    assert exit_info.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err


@pytest.mark.parametrize("shell", ["bash", "zsh", "tcsh"])
def test_shell_completion(shell: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["completion", shell]) == 0
    script = capsys.readouterr().out
    words = ["openel-async", "demo", "replay", "validate", "--log-level"]
    if shell != "tcsh":  # shtab's tcsh script completes commands, not every option
        words.append("--foxglove-port")
    for word in words:
        assert word in script, (shell, word)


def test_tap_options_after_the_app_name_record(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.mcap"
    argv = ["run", "twoaxis", "--virtual", "--duration", "0.2", "--no-live", "--record",
            str(out), "--foxglove", "--foxglove-port", "0"]  # fmt: skip
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "Foxglove live view on ws://127.0.0.1:" in captured.out
    assert read_recording(out).messages


APP_WITH_RECORD = """\
import argparse
from openel_async.app import AppInfo

async def main(ctx):
    parser = argparse.ArgumentParser(prog=ctx.prog)
    group = parser.add_argument_group("mine")
    group.add_argument("--record")
    print("app got", parser.parse_args(ctx.argv).record)
    return 0

APP_INFO = AppInfo(name="clash", description="an app with its own --record", main=main)
"""


def test_an_app_option_named_like_a_tap_option_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    app = tmp_path / "clash.py"
    app.write_text(APP_WITH_RECORD)
    assert main(["run", str(app), "--record", str(tmp_path / "x.mcap")]) == 2
    captured = capsys.readouterr()
    assert f"openel-async run {app}: the app has an option --record of its own" in captured.err
    assert "app got" not in captured.out
    assert main(["run", str(app), "--", "--record", "mine.log"]) == 0  # after '--': the app's
    assert "app got mine.log" in capsys.readouterr().out
    assert main(["run", str(app), "--record"]) == 2
    assert "openel-async run: --record needs a value" in capsys.readouterr().err


def test_devices_lists_without_python_reprs(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "  motor" in out and "openel_sim.motor.SimMotor" in out
    assert not re.search(r"<class |\('|\[\(|Error\(", out), out
