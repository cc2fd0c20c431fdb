"""arm6_pick_place: the 6-DoF MuJoCo arm picks the box up with its suction cup and places it.

The app is :mod:`openel_apps.arm6_pick_place`, shipped in the wheel and registered as
``arm6`` (``uv run openel-async run arm6 [options]`` or ``uv run openel-async demo --app
arm6``); this file keeps the path ``uv run openel-async run apps/arm6_pick_place.py
[--virtual | --realtime] [--duration S] [--place X Y] [--out DIR] [--no-live]`` working. ``--help``
lists every option; see docs/apps.md.
"""

from __future__ import annotations

from openel_apps.arm6_pick_place import (
    APP_INFO,
    Arm6Kinematics,
    UnreachableError,
    main,
    plan_pick_place,
    run_pick_place,
)

__all__ = [
    "APP_INFO",
    "Arm6Kinematics",
    "UnreachableError",
    "main",
    "plan_pick_place",
    "run_pick_place",
]
