"""Issue 26: a command held up on the way (a partition; TCP retransmitting it once healed)
is refused by the server, not executed late. Executes carry their send time and time to
live (docs/wire.md, "Freshness"); here the send times are forged, so no clock or network
delay is involved."""

from __future__ import annotations

import time

import anyio
import pytest
import zenoh

from openel_async import ReturnCode
from openel_async.surface import CommandMessage, Device, compact
from openel_zenoh import RemoteSurface
from openel_zenoh.freshness import CLOCK_DRIFT, DelayBaseline, freshness

from .conftest import client_cfg, free_port, session, sim_server


def message(function: str, **arguments: object) -> bytes:
    return compact.encode(Device("Motor", (CommandMessage.call(function, "", **arguments),)))


def return_code(reply: bytes) -> int:
    results = compact.device_from_compact(reply).commands[0].results
    assert results is not None
    return int(results.value("return_code"))


def sent(seconds_ago: float, ttl: float = 1.0) -> str:
    now_us = time.monotonic_ns() // 1000
    return f"sent_us={now_us - round(seconds_ago * 1e6)};ttl_us={round(ttl * 1e6)}"


async def test_an_execute_older_than_its_time_to_live_is_refused_and_not_executed() -> None:
    port = free_port()
    async with (
        sim_server(port) as (server, motors, _),
        session(client_cfg(port)) as zs,
        RemoteSurface(zs, "test") as remote,
    ):
        await remote.wait_server(5)
        execute = remote.keys.execute
        with anyio.fail_after(10):
            # The first one sets the client's baseline (arrival - send time).
            reply = await remote.query(execute, message("GetPosition", logical_id=0), sent(0))
            assert return_code(reply) == ReturnCode.HAL_OK
            # Sent 3 s ago with a time to live of 1 s: held up on the way.
            stale = message("SetPosition", logical_id=0, position=0.5)
            reply = await remote.query(execute, stale, sent(3.0))
            assert return_code(reply) == ReturnCode.HAL_NO_CONNECTED
            results = compact.device_from_compact(reply).commands[0].results
            assert results is not None and "stale command" in str(results.value("message"))
            assert server.refused_stale == 1
            assert motors[0].commands == 0  # nothing commanded
            # Late but within its time to live: executed.
            reply = await remote.query(execute, stale, sent(0.5))
            assert return_code(reply) == ReturnCode.HAL_OK
            assert server.refused_stale == 1 and motors[0].commands == 1
            # Reads are refused the same way (their reply would find nobody waiting).
            reply = await remote.query(execute, message("GetPosition", logical_id=0), sent(2.0))
            assert return_code(reply) == ReturnCode.HAL_NO_CONNECTED
            # Without the parameters (a client of its own), executed whenever it arrives.
            reply = await remote.query(execute, message("GetPosition", logical_id=0))
            assert return_code(reply) == ReturnCode.HAL_OK
            # RemoteSurface sends them with every execute: half its timeout to live.
            assert remote.execute_parameters().endswith(f";ttl_us={round(remote.timeout * 5e5)}")


async def test_a_client_clock_running_slow_is_not_taken_for_growing_delays() -> None:
    """The baseline may rise by CLOCK_DRIFT a second: a client whose clock falls behind
    the server's by less than that keeps being served."""
    port = free_port()
    async with (
        sim_server(port) as (server, _, _),
        session(client_cfg(port)) as zs,
        RemoteSurface(zs, "test") as remote,
    ):
        await remote.wait_server(5)
        read = message("GetPosition", logical_id=0)
        with anyio.fail_after(10):
            await remote.query(remote.keys.execute, read, sent(0, ttl=0.2))
            started = time.monotonic()
            await anyio.sleep(0.3)
            behind = 0.5 * CLOCK_DRIFT * (time.monotonic() - started) + 0.15
            # 0.15 s late against a 0.2 s time to live, plus a drift the allowance covers.
            reply = await remote.query(remote.keys.execute, read, sent(behind, ttl=0.2))
            assert return_code(reply) == ReturnCode.HAL_OK
            assert server.refused_stale == 0


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        ("", (None, 0.0)),
        ("sent_us=2000000;ttl_us=500000", (2.0, 0.5)),
        ("other=1", (None, 0.0)),
    ],
)
def test_freshness_parameters(parameters: str, expected: tuple[float | None, float]) -> None:
    assert freshness(zenoh.Parameters(parameters)) == expected


def test_malformed_freshness_parameters_are_ignored() -> None:
    sent_s, ttl = freshness(zenoh.Parameters("sent_us=soon;ttl_us=1"))
    assert sent_s != sent_s and ttl == 0.0  # NaN: served as if absent


def test_the_baseline_is_the_fastest_delivery_and_rises_with_the_drift_allowance() -> None:
    baseline = DelayBaseline()

    def deadline(received: float, delay: float, ttl: float = 1.0) -> float:
        """A query arriving at ``received`` that spent ``delay`` on the way (the client's
        clock is 100 s behind the server's, so delays are 100 s and a little)."""
        return baseline.deadline(received, received - delay, ttl)

    assert deadline(10.0, 100.010) == 11.0  # the first one is its own baseline
    assert deadline(11.0, 100.002) == 12.0  # faster: the new baseline
    assert deadline(12.0, 102.502) == pytest.approx(10.501)  # 2.5 s late: stale on arrival
    # 1000 s later the baseline may have risen by 1000 * CLOCK_DRIFT = 1 s: a client whose
    # clock lost 0.5 s meanwhile is not taken for late (without the allowance it would be).
    assert CLOCK_DRIFT == 1e-3
    assert deadline(1012.0, 100.502, ttl=0.1) == pytest.approx(1012.1)
