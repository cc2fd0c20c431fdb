"""The app ``pantilt``: the RT component ``PanTilt`` of ``RTC.yaml`` (next to this file), run as
``openel-async run pantilt [--duration S] [--virtual] [--set NAME=VALUE]...`` or
``openel-async run apps/pan_tilt/RTC.yaml``. The profile names its implementation,
``pan_tilt:PanTilt`` (:mod:`.pan_tilt`, imported only when the profile runs). Its two axes
are the actuators ``pan`` and ``tilt`` of a rig file: :data:`SIM_RIG` unless the
configuration says otherwise (``--set rig=FILE``, ``--set sim=true``)."""

from __future__ import annotations

from pathlib import Path

from openel_async.app import AppInfo

PROFILE = Path(__file__).with_name("RTC.yaml")
RIGS = Path(__file__).parents[1] / "rigs"
"""The rigs shipped with the apps: the configuration parameter ``rig`` may name one by its
file name."""
SIM_RIG = RIGS / "pantilt-sim.yaml"
"""The default rig: the head on two ``openel_sim`` motors."""

APP_INFO = AppInfo(
    name="pantilt",
    description="an RT component from its RTC Profile: a Lissajous scan of a pan-tilt head on "
    "two simulated motors (or any rig: --rig FILE), with scan and hold modes",
    profile=PROFILE,
    takes_rig=True,
)
"""The entry point ``pantilt`` of the ``openel_async.apps`` group."""
