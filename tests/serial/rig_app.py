"""A test app (``openel-async run rig_app.py --rig FILE``): opens its rig, whose actuators are
Dynamixel servos, and streams position goals to every one of them every 10 ms (a slow sine)
for ever; prints ``ready`` once each servo took a few goals. The rig arms the servos' Bus
Watchdogs (``safety.watchdog_timeout``); the test kills the app with SIGKILL."""

from __future__ import annotations

import math

import anyio

from openel_async import MonotonicClock, Request
from openel_async.app import AppContext, AppInfo

PERIOD_S = 0.01
READY_AFTER = 10
"""Goals sent to each servo before ``ready``."""


async def main(ctx: AppContext) -> int:
    clock = ctx.use_clock(MonotonicClock())
    async with ctx.open_rig(clock=clock) as rig:
        start = clock.now_ns()
        sent = 0
        while True:
            t = (clock.now_ns() - start) / 1e9
            for actuator in rig.actuators:
                await actuator.set_value(0.5 * math.sin(math.pi * t), Request.POSITION)
            sent += 1
            if sent == READY_AFTER:
                print("ready", flush=True)
            await anyio.sleep(PERIOD_S)


APP_INFO = AppInfo(
    name="rig_app", description="streams servo goals until killed", main=main, takes_rig=True
)
