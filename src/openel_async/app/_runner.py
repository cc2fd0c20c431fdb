"""Running an app to its exit status: :func:`run_app` starts the event loop, enters the
hooks around the app's ``main`` and turns a signal into a summary and an exit status."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence
from contextlib import AsyncExitStack
from functools import partial

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


def run_app(
    info: AppInfo,
    argv: Sequence[str],
    *,
    prog: str,
    hooks: Iterable[AppHook] = (),
    stop_label: str | None = None,
) -> int:
    """Run an app to its exit status (a synchronous entry point: it starts the event loop).

    SIGINT or SIGTERM cancels the app (its clean-ups run), prints ``summary (<title>,
    interrupted)`` with what the app did so far, and gives 130 or 143; the stderr line is
    ``<stop_label>: interrupted by ...`` (default ``prog``). ``SystemExit`` raised by the app
    (its argparse: ``--help``, a bad option) gives its code. :class:`AppUnavailable`
    propagates to the caller."""
    if info.profile is not None:
        from ..rtc.runner import run_profile_cli

        return int(run_profile_cli(info.profile, list(argv)))
    ctx = AppContext(argv, prog=prog, hooks=hooks)
    result = anyio.run(run_interruptible, partial(_run_main, info, ctx), backend="asyncio")
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
        for line in lines:
            print("  " + line)
        sys.stdout.flush()
        print(
            f"{stop_label or prog}: interrupted by {result.signum.name} "
            f"(exit status {result.exit_code})",
            file=sys.stderr,
        )
        return result.exit_code
    return int(result or 0)
