"""``openel-async calibrate RIG.yaml`` at work (its parser: :mod:`openel_serial.commands`).

It calibrates the Feetech STS servos of a rig as ``lerobot-calibrate`` does (:mod:`openel_serial.feetech_calibration`): every Feetech bus of the
rig is opened (``--bus`` to choose; ``--sim``: simulated servos, moved by a simulated hand),
the torque turned off, the user puts the arm in the middle of its range and presses Enter (the
homing offsets are written so that this pose reads step 2048, 0 rad), then moves each joint
through its full range by hand while the present positions and the minimum and maximum seen
are shown live, and presses Enter (the ranges are written as the angle limits). The
calibration file goes to ``--out``, else to the bus's ``calibration:`` option (a relative path
next to the rig file, whatever the current directory), else next to the rig
(``RIG.calibration.yaml``); joints of the file that were not calibrated this time are kept.

The command owns the terminal: prompts and the summary on standard output, the live table on
it while the joints are moved (on a terminal: rich's live display, log lines printed above
it; off a terminal: one line a second), logs on standard error. Input: one line (Enter) per
step from standard input; its end before a step is an error (exit status 1).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO, TypeAlias

import anyio
import anyio.to_thread
import msgspec

from openel_async.cli.commands import EXIT_USAGE, no_such_file
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_async.positioned import DocumentError
from openel_serial import feetech as ft

from .feetech_calibration import (
    CalibrationError,
    CalibrationFile,
    JointCalibration,
    JointReading,
    calibrate_servos,
    load_calibration,
    write_calibration,
)
from .feetech_peers import SimStsServo
from .feetech_port import FeetechPort
from .rigbus import SerialBusKind, SerialBusOptions

if TYPE_CHECKING:
    from rich.live import Live

    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]

__all__ = ["RangeDisplay", "SimulatedHand", "run"]

log = get_logger(__name__)

PROG = "openel-async calibrate"
EXIT_FAILED = 1
DEFAULT_SWEEP = 1.5
"""rad: how far the simulated hand moves a joint without ``position_limits`` each way."""


@dataclass(frozen=True)
class _Bus:
    name: str
    options: SerialBusOptions
    devices: tuple[Any, ...]
    joints: Mapping[str, int]
    sweeps: Mapping[str, tuple[float, float]]
    out: Path


def _plan(args: argparse.Namespace) -> list[_Bus]:
    from openel_async.rig import load_rig, resolve_rig

    resolved = resolve_rig(load_rig(args.rig))
    rig_path = Path(args.rig)
    default_out = rig_path.with_name(f"{rig_path.stem}.calibration.yaml")
    buses: list[_Bus] = []
    for name, bus in resolved.buses.items():
        options = bus.options
        if not isinstance(options, SerialBusOptions) or options.protocol != "feetech":
            continue
        if args.bus and name not in args.bus:
            continue
        joints = {d.name: int(d.params["servo_id"]) for d in bus.devices}
        sweeps: dict[str, tuple[float, float]] = {}
        for d in bus.devices:
            low, high = d.params.get("position_limits") or (-DEFAULT_SWEEP, DEFAULT_SWEEP)
            sweeps[d.name] = (float(low), float(high))
        out = Path(args.out or options.calibration or default_out)
        buses.append(_Bus(name, options, bus.devices, joints, sweeps, out))
    if args.bus:
        missing = sorted(set(args.bus) - {b.name for b in buses})
        if missing:
            raise BadParameterError("--bus", ", ".join(missing), "Feetech buses of the rig")
    if not buses:
        raise BadParameterError("rig", args.rig, "a rig with a serial bus of protocol: feetech")
    return buses


def run(args: argparse.Namespace) -> int:
    if no_such_file(PROG, args.rig):
        return EXIT_USAGE
    try:
        buses = _plan(args)
    except BadParameterError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        results = anyio.run(_calibrate, buses, args.sim, backend="asyncio")
    except BadParameterError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (HALError, TimeoutError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    by_file: dict[Path, dict[str, JointCalibration]] = {}
    for bus in buses:
        by_file.setdefault(bus.out, {}).update(results[bus.name])
    for path, joints in by_file.items():
        kept = _previous(path, joints)
        calibration = CalibrationFile(joints={**kept, **joints})
        stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
        write_calibration(
            path,
            calibration,
            comment=f"written by openel-async calibrate {args.rig}"
            f"{' --sim' if args.sim else ''} on {stamp}",
        )
        print(f"wrote {path} ({len(joints)} joints)", flush=True)
    return 0


def _previous(path: Path, joints: Mapping[str, JointCalibration]) -> dict[str, JointCalibration]:
    """The joints of an existing file that were not calibrated now (kept)."""
    if not path.exists():
        return {}
    try:
        old = load_calibration(path)
    except (DocumentError, OSError, UnicodeDecodeError) as exc:
        log.warning("feetech_calibration_replaced", file=str(path), reason=str(exc))
        return {}
    return {n: e for n, e in old.joints.items() if n not in joints}


async def _calibrate(buses: Sequence[_Bus], sim: bool) -> dict[str, dict[str, JointCalibration]]:
    from contextlib import AsyncExitStack

    kind = SerialBusKind()
    results: dict[str, dict[str, JointCalibration]] = {}
    for bus in buses:
        print(f"bus {bus.name}: {', '.join(f'{n} (id {i})' for n, i in bus.joints.items())}")
        async with AsyncExitStack() as stack:
            options = msgspec.structs.replace(bus.options, calibration=None)
            hand: SimulatedHand | None = None
            if sim:
                simulated = await stack.enter_async_context(
                    kind.simulate(bus.name, options, bus.devices)
                )
                options = simulated.options
                print(f"bus {bus.name}: {simulated.description}", flush=True)
                servos = {n: p for n, p in simulated.peers.items() if isinstance(p, SimStsServo)}
                hand = SimulatedHand(servos, bus.sweeps)
            port = await stack.enter_async_context(kind.open(bus.name, options))
            assert isinstance(port, FeetechPort)
            display = RangeDisplay(sys.stdout)
            try:
                results[bus.name] = await calibrate_servos(
                    port,
                    bus.joints,
                    _Prompter(hand, display).ask,
                    show=display.show,
                )
            finally:
                display.finish()
        for name, entry in results[bus.name].items():
            low, high = entry.radians()
            print(
                f"{name} (id {entry.id}): homing offset {entry.homing_offset}, range "
                f"{entry.range_min}..{entry.range_max} steps ({low:+.3f}..{high:+.3f} rad)",
                flush=True,
            )
    return results


class _Prompter:
    """``ask`` of the walk-through: the prompt on stdout, then one line from stdin."""

    def __init__(self, hand: SimulatedHand | None, display: RangeDisplay) -> None:
        self.hand = hand
        self.display = display

    async def ask(self, step: str, prompt: str) -> None:
        print(prompt, flush=True)
        if self.hand is None:
            await _read_line(step)
            return
        if step == "middle":
            self.hand.to_middle()
            await _read_line(step)
            return
        line = ""
        async with anyio.create_task_group() as tg:  # Enter after the hand is done
            tg.start_soon(self.hand.sweep, self.display)
            line = await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True)
        _check_line(line, step)


async def _read_line(step: str) -> None:
    _check_line(await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True), step)


def _check_line(line: str, step: str) -> None:
    if not line:
        raise CalibrationError(f"standard input ended before the {step} step was confirmed")


class SimulatedHand:
    """A person's hand on simulated servos (``--sim``): :meth:`to_middle` puts each rotor a
    little off step 2048 (``+ 40 x id`` steps: the homing offsets then differ from 0),
    :meth:`sweep` moves each joint in turn to its low and high ``sweeps`` (rad) and back,
    holding each pose for two displayed samples."""

    def __init__(
        self, servos: Mapping[str, SimStsServo], sweeps: Mapping[str, tuple[float, float]]
    ) -> None:
        self.servos = dict(servos)
        self.sweeps = dict(sweeps)

    def middle(self, name: str) -> int:
        return ft.CENTER_TICK + 40 * self.servos[name].id

    def to_middle(self) -> None:
        for name, servo in self.servos.items():
            servo.set_rotor(self.middle(name))

    async def sweep(self, display: RangeDisplay) -> None:
        for name, servo in self.servos.items():
            low, high = self.sweeps.get(name, (-DEFAULT_SWEEP, DEFAULT_SWEEP))
            middle = self.middle(name)
            for rad in (low, high, 0.0):
                servo.set_rotor(middle + ft.rad_to_ticks(rad) - ft.CENTER_TICK)
                with anyio.move_on_after(5):  # bounded; the walk-through streams every cycle
                    await display.samples_after(2)


class RangeDisplay:
    """The live table of the range step: on a terminal, rich's live display (output and log
    lines printed above it); off one, one line a second."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.tty = _is_tty(stream)
        self.samples = 0
        self._waiters: list[tuple[int, anyio.Event]] = []
        self._live: Live | None = None
        self._last = 0.0
        self._readings: list[JointReading] = []

    def show(self, readings: list[JointReading]) -> None:
        self.samples += 1
        self._readings = readings
        for target, event in list(self._waiters):
            if self.samples >= target:
                event.set()
        now = time.monotonic()
        if now - self._last < (0.1 if self.tty else 1.0):
            return
        self._last = now
        self._render()

    async def samples_after(self, count: int) -> None:
        """Return once ``count`` more samples have been shown."""
        event = anyio.Event()
        entry = (self.samples + count, event)
        self._waiters.append(entry)
        try:
            await event.wait()
        finally:
            self._waiters.remove(entry)

    def _render(self) -> None:
        readings = self._readings
        if not self.tty:
            line = " | ".join(f"{r.name} {r.position} [{r.low}..{r.high}]" for r in readings)
            self.stream.write(line + "\n")
            self.stream.flush()
            return
        from rich.console import Console
        from rich.live import Live

        table = _table(readings)
        if self._live is None:
            console = Console(file=self.stream, highlight=False)
            self._live = Live(
                table,
                console=console,
                auto_refresh=False,
                redirect_stdout=True,
                redirect_stderr=_is_tty(sys.stderr),
            )
            self._live.start(refresh=True)
        else:
            self._live.update(table, refresh=True)

    def finish(self) -> None:
        if self._readings and self._live is None and not self.tty:
            self._render()  # the last values, off a terminal
        elif self._live is not None:
            self._live.update(_table(self._readings), refresh=True)
            self._live.stop()
            self._live = None


def _table(readings: list[JointReading]) -> Any:
    from rich.table import Table

    table = Table(title="move each joint through its full range, then press Enter")
    for column in ("joint", "id", "position", "min", "max", "range (deg)"):
        table.add_column(column, justify="left" if column == "joint" else "right")
    for r in readings:
        table.add_row(
            r.name,
            str(r.id),
            str(r.position),
            str(r.low),
            str(r.high),
            f"{r.span_rad * 180 / 3.141592653589793:.1f}",
        )
    return table


def _is_tty(stream: TextIO | None) -> bool:
    try:
        return stream is not None and stream.isatty()
    except (ValueError, AttributeError):
        return False


"""``openel-async calibrate``."""
