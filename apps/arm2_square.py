"""arm2_square: the 2-DoF MuJoCo arm traces a square with its tip.

The app is :mod:`openel_apps.arm2_square`, shipped in the wheel and registered as ``arm2``
(``uv run openel-async run arm2 [options]``); this file keeps the path
``uv run openel-async run apps/arm2_square.py [--virtual | --realtime] [--duration S]
[--laps N] [--side M] [--elbow up|down] [--out DIR] [--no-live]`` working. ``--help`` lists every
option; see docs/apps.md.
"""

from __future__ import annotations

from openel_apps.arm2_square import APP_INFO, PlanarArm, UnreachableError, main, run_square

__all__ = ["APP_INFO", "PlanarArm", "UnreachableError", "main", "run_square"]
