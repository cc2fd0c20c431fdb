"""Waiting for an anyio Event until a deadline on a Clock (virtual clocks included)."""

from __future__ import annotations

import anyio

from ...clock import Clock


async def wait_event(clock: Clock, event: anyio.Event, deadline_ns: int) -> bool:
    """Wait for ``event`` until ``deadline_ns`` on ``clock``; False on timeout."""
    if event.is_set():
        return True
    with anyio.CancelScope() as scope:
        async with anyio.create_task_group() as tg:

            async def alarm() -> None:
                await clock.sleep_until(deadline_ns)
                scope.cancel()

            tg.start_soon(alarm)
            await event.wait()
            tg.cancel_scope.cancel()
    return not scope.cancelled_caught
