"""arm2_square: the 2-DoF MuJoCo arm traces a square with its tip.

Run it with ``uv run openel-async run apps/arm2_square.py [--realtime] [--duration S]
[--laps N] [--side M] [--elbow up|down] [--out DIR] [--no-live]``; ``--help`` lists every
option.  See docs/apps.md.

The application lives in the package (:mod:`openel_async.cli.arm2_square`) because it is also
the default ``openel-async demo``, which must work from an installed wheel (``apps/`` is not
shipped).  What it does, in short:

1. inverse kinematics of points along each edge of a 15 cm square (elbow up or down, with a
   clear error for a point out of reach);
2. an ``AxisGroup`` over the ``shoulder`` and ``elbow`` Actuators of a ``MujocoSim`` streams the
   joint setpoints on an ``EventTimer`` of the simulation clock: one ``follow()`` of timed IK
   waypoints per edge, both joints arriving at each corner on the same tick;
3. the ``tip_pos`` framepos sensor, read through an OpenEL ``Sensor`` at every tick, measures the
   tip's deviation from the ideal edges (live progress line, summary);
4. at the end: PNG plots (joints commanded vs actual, tip path) and a PNG snapshot of the scene
   in ``out/arm2_square/`` (``--out`` to change).
"""

from __future__ import annotations

from openel_async.cli.arm2_square import PlanarArm, UnreachableError, main, run_square

__all__ = ["PlanarArm", "UnreachableError", "main", "run_square"]
