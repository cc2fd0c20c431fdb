"""SYNC declared in a rig: a CAN bus's ``sync:`` makes opening the rig start the bus's
CanSync on the timer driving it (BusKind.bind_timer), with no app code naming CanSync."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import anyio
import pytest
import yaml

from openel_async import BadParameterError
from openel_async.rig import load_rig, open_rig, resolve_rig
from openel_can import CanBus, CanSync, Cia402CyclicDrive
from openel_can.sim.cia402 import SimCia402Drive

from .conftest import wait_until


def _rig(tmp_path: Path, sync: Any, *, group: bool = True, timers: bool = True) -> Path:
    bus: dict[str, Any] = {"type": "can", "interface": "virtual", "bitrate": 1_000_000}
    if sync is not None:
        bus["sync"] = sync
    rig: dict[str, Any] = {
        "namespace": "sync",
        "buses": {"can0": bus},
        "components": [
            {
                "name": f"AXIS_{n}",
                "driver": "can",
                "device": "cia402_drive",
                "bus": "can0",
                "params": {"node_id": n, "mode": "csp", "heartbeat_ms": 100},
                "limits": {"velocity": 4.0, "acceleration": 40.0},
            }
            for n in (1, 2)
        ],
        "safety": {"watchdog_timeout": None, "on_exit": "hold"},
    }
    if timers:
        rig["timers"] = {"slow": {"period_ms": 10.0}, "cycle": {"period_ms": 2.0}}
    if group:
        rig["groups"] = {
            "pair": {"axes": ["AXIS_1", "AXIS_2"], "timer": "cycle", "limits": {"max_jerk": 400.0}}
        }
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig, sort_keys=False))
    return path


async def test_the_rig_produces_sync_on_the_groups_timer(tmp_path: Path) -> None:
    resolved = resolve_rig(load_rig(_rig(tmp_path, {"counter": 4})))
    assert resolved.buses["can0"].timer == "cycle"
    load = resolved.buses["can0"].load
    assert load is not None and "2 axes streamed every 2 ms" in load.detail
    async with open_rig(resolved, sim=True) as rig:
        bus = rig.buses["can0"]
        assert isinstance(bus, CanBus)
        sync = CanSync.of(bus)
        assert sync.running and sync.timer is rig.timer("cycle") and sync.counter_overflow == 4
        sims = [rig.peers[f"AXIS_{n}"] for n in (1, 2)]
        assert all(isinstance(s, SimCia402Drive) for s in sims)
        for sim in sims:  # written before the first SYNC
            assert sim.interpolation_period_ns() == 2_000_000 and sim.od[(0x1019, 0)].value == 4
        group = rig.group("pair")
        with anyio.fail_after(5):
            await (await group.move_to([0.1, -0.1]))
        drive = group.axes[0].device
        assert isinstance(drive, Cia402CyclicDrive) and drive.sync_source is sync
        await wait_until(lambda: len(sims[0].sync_counters) > 8)
        assert set(sims[0].sync_counters) == {1, 2, 3, 4}
        assert sync.stats.cycles > 8
    assert not sync.running  # stopped with the rig


def test_rig_check_refuses_sync_without_a_timer_a_bad_counter_or_key(tmp_path: Path) -> None:
    cases: list[tuple[dict[str, Any], dict[str, bool], str, str]] = [
        ({}, {"group": False, "timers": False}, "sync", "a timer driving the bus"),
        ({"counter": 1}, {}, "sync.counter", "2..240"),
        ({"period_ms": 2}, {}, "period_ms", "sync"),
    ]
    for sync, flags, parameter, words in cases:
        with pytest.raises(BadParameterError) as err:
            resolve_rig(load_rig(_rig(tmp_path, sync, **flags)))
        assert parameter in str(err.value) and words in str(err.value), str(err.value)
    # no group on the bus: the rig's fastest timer drives it
    assert resolve_rig(load_rig(_rig(tmp_path, {}, group=False))).buses["can0"].timer == "cycle"
