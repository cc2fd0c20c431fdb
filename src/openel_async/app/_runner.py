"""Running an app to its exit status: :func:`run_app` starts the event loop, enters the
hooks around the app's ``main`` and turns a signal into a summary and an exit status."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence
from contextlib import AsyncExitStack
from functools import partial
from pathlib import Path

import anyio

from ._context import AppContext, AppHook, AppInfo, AppUnavailable
from ._interrupt import Interrupted, run_interruptible

__all__ = ["run_app"]


async def _run_main(info: AppInfo, ctx: AppContext) -> int | AppUnavailable | SystemExit | None:
    """The app's exit status, or the AppUnavailable or SystemExit (its argparse) it raised,
    returned so that no task group wraps it in an exception group."""
    assert info.main is not None
    try:
        async with AsyncExitStack() as stack:
            for hook in ctx.hooks:
                await stack.enter_async_context(hook)
            return await info.main(ctx)
    except (AppUnavailable, SystemExit) as exc:
        return exc


async def _leave_rigs_safe(ctx: AppContext) -> None:
    """On a stop signal, before the app is cancelled: its timers stop (no more setpoints from
    their observers) and each open rig leaves its actuators as ``safety.on_exit`` says while
    its buses still answer."""
    for timer in ctx.timers:
        if timer.state.value == "Running":
            timer.stop_timer()
    for rig in ctx.rigs:
        await rig.leave_safe()


def run_app(
    info: AppInfo,
    argv: Sequence[str],
    *,
    prog: str,
    hooks: Iterable[AppHook] = (),
    stop_label: str | None = None,
    rig: str | Path | None = None,
    sim: bool = False,
) -> int:
    """Run an app to its exit status (a synchronous entry point: it starts the event loop).

    SIGINT or SIGTERM cancels the app (its clean-ups run), prints ``summary (<title>,
    interrupted)`` with what the app did so far, and gives 130 or 143; the stderr line is
    ``<stop_label>: interrupted by ...`` (default ``prog``). ``SystemExit`` raised by the app
    (its argparse: ``--help``, a bad option) gives its code. :class:`AppUnavailable`
    propagates to the caller.

    ``rig``: a rig file for an app that takes one (:attr:`AppInfo.takes_rig`), checked
    against the drivers before anything runs (a mistake: its message and 2); ``sim``: run
    the rig against simulated peers. A profile app that takes a rig gets them as its
    configuration settings ``rig`` and ``sim``. The state each rig the app opened left its actuators
    in is printed after the app's own summary."""
    label = stop_label or prog
    if (rig is not None or sim) and not info.takes_rig:
        print(f"{label}: --rig and --sim need an app that opens a rig ({info.name} does not)",
              file=sys.stderr)  # fmt: skip
        return 2
    resolved = None
    if rig is not None:
        from ..errors import BadParameterError
        from ..rig import load_rig, resolve_rig

        try:
            resolved = resolve_rig(load_rig(rig))
        except BadParameterError as exc:
            print(f"{label}: {exc}", file=sys.stderr)
            return 2
    if info.profile is not None:
        # A profile app that takes a rig reads it from its configuration parameters
        # ``rig`` and ``sim`` (pantilt): the options become their settings.
        settings = [] if rig is None else ["--set", f"rig={Path(rig).resolve()}"]
        settings += ["--set", "sim=true"] if sim else []
        args = [*settings, *argv]
        # --help and a mistaken option answered before the RTC machinery is loaded
        from ..run_profile_args import parse_profile_run_args

        try:
            parse_profile_run_args(args)
        except SystemExit as exc:
            return int(exc.code or 0) if exc.code in (0, None) else 2
        from ..rtc.runner import run_profile_cli

        return int(run_profile_cli(info.profile, args))
    if info.parser is not None:
        # --help and a mistaken option answered before the event loop starts
        try:
            info.parser(prog).parse_args(list(argv))
        except SystemExit as exc:
            return exc.code if isinstance(exc.code, int) else 0 if exc.code is None else 2
    ctx = AppContext(argv, prog=prog, hooks=hooks, rig=resolved, sim=sim)
    try:
        result = anyio.run(
            run_interruptible,
            partial(_run_main, info, ctx),
            partial(_leave_rigs_safe, ctx),
            backend="asyncio",
        )
    except BaseException:  # the app failed: still say how its rigs left the machine
        for rig_ in ctx.rigs:
            print(f"{label}: {rig_.exit_line()}", file=sys.stderr)
        raise
    exit_lines = [r.exit_line() for r in ctx.rigs]
    if isinstance(result, AppUnavailable):
        raise result
    if isinstance(result, SystemExit):  # the app's argparse: --help (0) or a bad option (2)
        if result.code is None or isinstance(result.code, int):
            return result.code or 0
        print(result.code, file=sys.stderr)
        return 1
    if isinstance(result, Interrupted):
        print(f"\nsummary ({ctx.title or info.name}, interrupted)")
        lines = [*result.lines(), *(ctx.progress() if ctx.progress is not None else [])]
        lines += exit_lines
        for line in lines:
            print("  " + line)
        sys.stdout.flush()
        print(
            f"{stop_label or prog}: interrupted by {result.signum.name} "
            f"(exit status {result.exit_code})",
            file=sys.stderr,
        )
        return result.exit_code
    for line in exit_lines:
        print("  " + line)
    return int(result or 0)
