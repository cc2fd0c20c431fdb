"""The files a rig's bus options name (a Feetech calibration file, a MuJoCo model) are found
relative to the rig file, whatever the current directory (BusKind.resolve_paths)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from openel_async.rig import load_rig, resolve_rig
from openel_mujoco.models import model_path

SERIAL_RIG = """\
buses:
  arm: {type: serial, protocol: feetech, device: /dev/ttyACM0, baudrate: 1000000,
        calibration: cal/arm.calibration.yaml}
components:
  - {name: J1, driver: serial, device: feetech_sts3215, bus: arm, params: {servo_id: 1}}
"""

MUJOCO_RIG = """\
buses:
  sim: {type: mujoco, model: models/arm2.xml}
components:
  - {name: shoulder, driver: mujoco, device: joint, bus: sim}
"""


def test_relative_paths_are_the_rig_files_neighbours(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rigs = tmp_path / "rigs"
    rigs.mkdir()
    (rigs / "serial.yaml").write_text(SERIAL_RIG)
    (rigs / "models").mkdir()
    shutil.copy(model_path("arm2"), rigs / "models" / "arm2.xml")
    (rigs / "mujoco.yaml").write_text(MUJOCO_RIG)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    serial = resolve_rig(load_rig(Path("..") / "rigs" / "serial.yaml"))
    calibration = serial.buses["arm"].options.calibration
    assert Path(calibration).resolve() == rigs / "cal" / "arm.calibration.yaml"
    mujoco = resolve_rig(load_rig(rigs / "mujoco.yaml"))  # the model loads from elsewhere
    assert Path(mujoco.buses["sim"].options.model) == rigs / "models" / "arm2.xml"


def test_a_shipped_model_and_an_absolute_path_stay_as_they_are(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(MUJOCO_RIG.replace("models/arm2.xml", "arm2"))
    assert resolve_rig(load_rig(rig)).buses["sim"].options.model == "arm2"
    absolute = str(model_path("arm2"))
    rig.write_text(MUJOCO_RIG.replace("models/arm2.xml", absolute))
    assert resolve_rig(load_rig(rig)).buses["sim"].options.model == absolute
