"""csp4: four CiA 402 drives in cyclic synchronous position (CSP), moved together by an
AxisGroup on SYNC from its timer: ``openel-async run csp4 [--rig FILE] [--sim]``.

- **Rig**: ``rigs/csp4.yaml`` by default (four drives, node ids 1-4, ``mode: csp``, on one
  CAN bus; ``--sim``: simulated drives on a python-can virtual bus). The app takes the
  rig's group :data:`GROUP` and its timer.
- **SYNC**: the rig's CAN bus says ``sync: {counter: 0}``: opening the rig starts the bus's
  SYNC producer on the timer driving it, the group's (each drive's 0x60C2 = the timer period
  first); from then on every tick sends the four RPDOs the group staged, then SYNC. The app
  names no CAN class: it reads the SYNC statistics through the drives (``sync_source``).
- **Motion**: :data:`MOVES`, each one ``move_to`` of the four axes, starting and arriving
  together; one line per move (time, largest error at the end from the drives' TPDOs, SYNC
  cycles so far and missed ones). Exit status 0 when every move was reached.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Final

from openel_async import HALError, Request
from openel_async.app import AppContext, AppInfo, DemoOptions

__all__ = ["APP_INFO", "GROUP", "MOVES", "RIG", "build_parser", "main"]

APP: Final = "csp4"
RIG: Final = Path(__file__).parent / "rigs" / "csp4.yaml"
GROUP: Final = "csp4"
"""The rig's AxisGroup the app moves (its timer produces the SYNC)."""
MOVES: Final = (
    (1.0, -1.0, 0.5, -0.5),
    (-0.5, 0.5, -1.5, 1.5),
    (2.0, 2.0, -2.0, -2.0),
    (0.0, 0.0, 0.0, 0.0),
)
"""Target positions (rad) of the four axes, move after move."""
TOLERANCE_RAD: Final = 2e-3
"""A move is reached when every axis ends within this of its target."""


def build_parser(prog: str = APP) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Four CiA 402 drives in cyclic synchronous position (CSP) on SYNC from "
        "the AxisGroup's timer, through a synchronized sequence of moves; rig "
        "apps/openel_apps/rigs/csp4.yaml by default (--sim: simulated drives).",
    )
    parser.add_argument(
        "--moves", type=int, default=len(MOVES), help=f"how many moves (1..{len(MOVES)})"
    )
    return parser


def _line(index: int, target: Sequence[float], seconds: float, error: float, sync: str) -> str:
    where = ", ".join(f"{x:+.2f}" for x in target)
    return (
        f"move {index}: [{where}] rad reached in {seconds:.3f} s, max error {error:.5f} rad, {sync}"
    )


async def main(ctx: AppContext) -> int:
    """The app ``csp4``: ``openel-async run csp4 [--rig FILE] [--sim] [--moves N]``."""
    parser = build_parser(ctx.prog)
    args = parser.parse_args(ctx.argv)
    if not 1 <= args.moves <= len(MOVES):
        parser.error(f"--moves {args.moves}: 1..{len(MOVES)}")
    ok = True
    async with ctx.open_rig(default=RIG) as rig:
        group = rig.group(GROUP)
        spec = rig.spec.component(group.axis_names[0])
        sync = getattr(group.axes[0].device, "sync_source", None)  # a cyclic CiA 402 drive's
        if sync is None or not sync.running:
            parser.error(
                f"group {GROUP}: its axes must be CiA 402 drives in a cyclic mode on a CAN bus "
                "with 'sync:' (the rig's SYNC producer)"
            )
        ctx.title = f"CSP, four axes ({rig.bus_descriptions.get(spec.bus or '', '')})"
        print(
            f"{ctx.prog}: {len(group.axes)} axes in CSP, SYNC every "
            f"{group.timer.period_ms:g} ms on {rig.bus_descriptions.get(spec.bus or '', '')}"
        )
        try:
            for index, target in enumerate(MOVES[: args.moves], start=1):
                started = time.perf_counter()
                await (await group.move_to(list(target)))
                seconds = time.perf_counter() - started
                actual = [await axis.get_value(Request.POSITION_ACTUAL) for axis in group.axes]
                error = max(abs(a - t) for a, t in zip(actual, target, strict=True))
                ok = ok and error <= TOLERANCE_RAD
                stats = sync.stats
                print(
                    _line(
                        index,
                        target,
                        seconds,
                        error,
                        f"SYNC cycles {stats.cycles} (missed {stats.missed})",
                    )
                )
        except HALError as exc:
            print(f"{ctx.prog}: a move failed: {exc}")
            return 1
        finally:
            stats = sync.stats
        print(
            f"summary (CSP, four axes): {'all' if ok else 'not all'} moves reached; "
            f"{stats.cycles} SYNC, {stats.missed} missed, {stats.rpdos} RPDOs, "
            f"{stats.late_feedback} late TPDO cycles"
        )
    return 0 if ok else 1


def demo_args(options: DemoOptions) -> list[str]:
    """``openel-async demo --app csp4``: no option of its own."""
    for name in ("bus", "duration", "inject_fault", "period_ms", "out"):
        if getattr(options, name, None) not in (None, False):
            raise ValueError(f"csp4 takes no --{name.replace('_', '-')}")
    return []


APP_INFO = AppInfo(
    name=APP,
    description="four CiA 402 drives in cyclic synchronous position (CSP) on SYNC from an "
    "AxisGroup's timer (rigs/csp4.yaml; --sim: simulated drives)",
    main=main,
    demo_args=demo_args,
    takes_rig=True,
    parser=build_parser,
)
"""The entry point ``csp4`` of the ``openel_async.apps`` group."""
