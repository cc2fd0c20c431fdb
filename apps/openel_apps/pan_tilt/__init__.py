"""The app ``pantilt``: the RT component ``PanTilt`` of ``RTC.yaml`` (next to this file), run as
``openel-async run pantilt [--duration S] [--virtual] [--set NAME=VALUE]...`` or
``openel-async run apps/pan_tilt/RTC.yaml``. The profile names its implementation,
``pan_tilt:PanTilt`` (:mod:`.pan_tilt`, imported only when the profile runs)."""

from __future__ import annotations

from pathlib import Path

from openel_async.app import AppInfo

PROFILE = Path(__file__).with_name("RTC.yaml")

APP_INFO = AppInfo(
    name="pantilt",
    description="an RT component from its RTC Profile: a Lissajous scan of a pan-tilt head on "
    "two simulated motors, with scan and hold modes",
    profile=PROFILE,
)
"""The entry point ``pantilt`` of the ``openel_async.apps`` group."""
