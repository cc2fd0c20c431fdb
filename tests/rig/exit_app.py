"""A test app: opens its rig (``--rig FILE [--sim]``), moves the first axis, prints
``ready``, then returns, raises or waits to be stopped by a signal (``--then``); after the rig
closed, however the run ended, it prints the state of each simulated peer."""

from __future__ import annotations

import argparse

import anyio

from openel_async import MonotonicClock, Request
from openel_async.app import AppContext, AppInfo


def _peer_state(peer: object) -> str:
    torque = getattr(peer, "torque_enabled", None)  # a simulated Dynamixel servo
    if torque is not None:
        return f"torque={'on' if torque else 'off'}"
    for name in ("axis_state", "power_state"):  # a simulated ODrive, a simulated CiA 402 drive
        value = getattr(peer, name, None)
        if value is not None:
            return f"{name}={getattr(value, 'name', value)}"
    return "?"


class ErrorPrinter:
    """Prints ``error NAME ID`` for each notify_error (the test waits for these lines)."""

    def notify_event(self, source: object, event_id: int) -> None:
        pass

    def notify_error(self, source: object, error_id: int) -> None:
        print(f"error {getattr(source, 'device_name', '?')} {int(error_id)}", flush=True)


async def main(ctx: AppContext) -> int:
    parser = argparse.ArgumentParser(prog=ctx.prog)
    parser.add_argument("--then", choices=("return", "raise", "wait"), default="return")
    args = parser.parse_args(ctx.argv)
    clock = ctx.use_clock(MonotonicClock())
    peers: dict[str, object] = {}
    try:
        async with ctx.open_rig(clock=clock) as rig:
            peers.update(rig.peers)
            for actuator in rig.actuators:
                actuator.add_observer(ErrorPrinter())
            first = rig.actuators[0]
            motion = await first.set_value(0.3, Request.POSITION)
            with anyio.fail_after(10):
                await motion
            print("ready", flush=True)
            if args.then == "raise":
                raise RuntimeError("the app failed")
            if args.then == "wait":
                await anyio.sleep_forever()
    finally:
        for name, peer in sorted(peers.items(), key=lambda item: item[0]):
            print(f"peer {name} {_peer_state(peer)}", flush=True)
    return 0


APP_INFO = AppInfo(name="exit_app", description="a rig's exit paths", main=main, takes_rig=True)
