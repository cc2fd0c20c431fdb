"""A rig loads the drivers it names, not every installed one; a driver or bus type it does
not find is refused with the list of every installed one."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from openel_async.errors import BadParameterError
from openel_async.rig import load_rig, resolve_rig

RIGS = Path(__file__).parents[2] / "apps" / "openel_apps" / "rigs"

PROBE = """
import sys
from openel_async.rig import load_rig, resolve_rig
resolve_rig(load_rig(sys.argv[1]))
print(sorted(m for m in ("openel_can", "openel_mujoco", "openel_serial", "openel_zenoh", "can",
                         "mujoco", "serial") if m in sys.modules))
"""


def test_a_sim_rig_imports_no_other_driver() -> None:
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(RIGS / "twoaxis-sim.yaml")],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_a_missing_driver_or_bus_type_lists_every_installed_one(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text("components:\n  - {name: M, driver: nosuch, device: motor}\n")
    with pytest.raises(BadParameterError) as info:
        resolve_rig(load_rig(rig))
    assert all(name in str(info.value) for name in ("can", "mujoco", "serial", "sim", "zenoh"))
    rig.write_text(
        "buses:\n  b0: {type: nosuch}\ncomponents:\n  - {name: M, driver: sim, device: motor}\n"
    )
    with pytest.raises(BadParameterError) as info:
        resolve_rig(load_rig(rig))
    assert "buses.b0.type" in str(info.value)
    assert all(name in str(info.value) for name in ("can", "mujoco", "serial"))
