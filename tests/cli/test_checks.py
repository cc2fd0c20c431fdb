"""Options checked before anything runs, rates the context cannot run, profiles that name code
by path, ``profile convert`` to a missing folder, and output files written whole."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import anyio
import pytest

from openel_async.app import atomic_output, collect_written, run_interruptible
from openel_async.cli import main
from openel_async.cli.logs import reset_logging

ROOT = Path(__file__).resolve().parents[2]
PAN_TILT = ROOT / "apps" / "pan_tilt" / "RTC.yaml"


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    yield
    reset_logging()


# -- demo options -------------------------------------------------------------------------------


@pytest.mark.parametrize("period", ["nan", "inf", "1e-9", "0.05", "5000"])
def test_sim_demo_refuses_a_period_it_cannot_run(
    period: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["demo", "--bus", "sim", "--virtual", "--no-live", "--period-ms", period]) == 2
    captured = capsys.readouterr()
    assert f"--period-ms {float(period):g}: from 0.1 to 1000 ms" in captured.err
    assert "summary" not in captured.out


@pytest.mark.parametrize("period", ["nan", "inf", "1e-9", "0.5", "1.5", "200"])
def test_mujoco_demo_refuses_a_period_off_the_physics_step(
    period: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = tmp_path / "out"
    args = ["demo", "--virtual", "--no-live", "--period-ms", period, "--out", str(out_dir)]
    assert main(args) == 2
    assert (
        f"--period-ms {float(period):g}: a whole multiple of the 1 ms physics step"
        in capsys.readouterr().err
    )
    assert not out_dir.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--duration", "inf"], "--duration inf: a finite number of seconds > 0"),
        (["--duration", "nan"], "--duration nan: a finite number of seconds > 0"),
        (["--duration", "1e6", "--period-ms", "0.1"], "1e+10 timer ticks on the virtual clock"),
        (["--out", "x"], "--out needs --bus mujoco"),
    ],
)
def test_sim_demo_checks_every_option_first(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    started = time.monotonic()
    assert main(["demo", "--bus", "sim", "--virtual", "--no-live", *args]) == 2
    assert message in capsys.readouterr().err
    assert time.monotonic() - started < 5.0  # refused, not run


@pytest.mark.parametrize("app", ["arm2", "arm6"])
def test_demo_refuses_an_out_that_is_a_file_before_running(
    app: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    existing = tmp_path / "a-file"
    existing.write_text("keep me")
    started = time.monotonic()
    assert main(["demo", "--app", app, "--virtual", "--no-live", "--out", str(existing)]) == 2
    assert main(["demo", "--app", app, "--virtual", "--out", str(existing / "sub")]) == 2
    captured = capsys.readouterr()
    assert f"--out {existing}: exists and is not a directory" in captured.err
    assert f"{existing} is a file, not a directory" in captured.err
    assert "summary" not in captured.out
    assert existing.read_text() == "keep me"
    assert time.monotonic() - started < 10.0  # refused before the model loads and runs


def test_mujoco_demo_refuses_a_duration_over_the_limit(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--virtual", "--no-live", "--duration", "1e9"]) == 2
    assert "--duration 1e+09: a number of seconds > 0 and at most 600" in (capsys.readouterr().err)


# -- profile runs ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rate", "1e9", "--duration", "1", "--virtual"], "--rate: the rate must be a number"),
        (["--rate", "1e4", "--duration", "1000", "--virtual"], "1e+07 cycles on the virtual"),
        (["--rate", "2000", "--duration", "600", "--virtual"], "1.2e+06 cycles"),
        (["--rate", "1e6", "--duration", "1"], "--rate: the rate must be a number of Hz"),
    ],
)
def test_run_refuses_a_rate_the_context_cannot_run(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    started = time.monotonic()
    assert main(["run", str(PAN_TILT), *args]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert time.monotonic() - started < 5.0


def test_run_accepts_the_largest_virtual_work(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(PAN_TILT), "--rate", "10000", "--duration", "0.5", "--virtual"]) == 0
    assert "cycles             5000" in capsys.readouterr().out


@pytest.mark.parametrize("where", ["absolute", "dotdot", "subdir"])
def test_a_profile_cannot_name_code_by_path(
    where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    evil_dir = tmp_path / "elsewhere"
    evil_dir.mkdir()
    marker = tmp_path / "executed"
    code = f"open({str(marker)!r}, 'w').close()\n"
    (evil_dir / "evil.py").write_text(code)
    (tmp_path / "evil.py").write_text(code)
    (tmp_path / "profiles").mkdir()
    sub = tmp_path / "profiles" / "sub"
    sub.mkdir()
    (sub / "evil.py").write_text(code)
    name = {
        "absolute": f"{evil_dir / 'evil'}:PanTilt",
        "dotdot": "../evil:PanTilt",
        "subdir": "sub/evil:PanTilt",
    }[where]
    text = PAN_TILT.read_text().replace('"pan_tilt:PanTilt"', f'"{name}"')
    profile = tmp_path / "profiles" / "RTC.yaml"
    profile.write_text(text)
    assert main(["profile", "validate", str(profile), "--implementation"]) == 1
    assert main(["run", str(profile), "--virtual", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "with a Python module name" in err and "not a path" in err
    assert not marker.exists()


def test_help_says_that_run_and_validate_execute_code(capsys: pytest.CaptureFixture[str]) -> None:
    for args in (["run", "--help"], ["profile", "validate", "--help"]):
        with pytest.raises(SystemExit):
            main(args)
        assert "EXECUTE" in capsys.readouterr().out
    assert main(["run", str(PAN_TILT), "--help"]) == 0
    assert "executes the Python module the profile names" in " ".join(
        capsys.readouterr().out.split()
    )


# -- profile convert --------------------------------------------------------------------------------


def test_convert_names_the_missing_output_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "missing" / "RTC.xml"
    assert main(["profile", "convert", str(PAN_TILT), str(out)]) == 1
    err = capsys.readouterr().err
    assert f"{out}: cannot write: the folder {out.parent} does not exist" in err
    assert "no such file" not in err
    assert main(["profile", "convert", str(PAN_TILT), str(tmp_path / "RTC.txt")]) == 1
    assert "unknown profile format '.txt'" in capsys.readouterr().err
    written = tmp_path / "RTC.xml"
    assert main(["profile", "convert", str(PAN_TILT), str(written)]) == 0
    assert written.read_text().startswith("<?xml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["RTC.xml"]  # no temporary left


# -- output files ---------------------------------------------------------------------------------


async def test_a_cancelled_write_leaves_no_file(tmp_path: Path) -> None:
    target = tmp_path / "plot.png"

    async def write_then_hang() -> None:
        with atomic_output(target) as partial:
            assert partial.parent == tmp_path and partial.suffix == ".png"
            partial.write_bytes(b"half")
            await anyio.sleep_forever()

    with anyio.move_on_after(0.01):
        await write_then_hang()
    assert _entries(tmp_path) == []

    async def write() -> list[Path]:
        with atomic_output(target) as partial:
            partial.write_bytes(b"whole")
        return collect_written()

    assert await run_interruptible(write) == [target]
    assert target.read_bytes() == b"whole"
    assert _entries(tmp_path) == [target]


def _entries(folder: Path) -> list[Path]:
    return sorted(folder.iterdir())
