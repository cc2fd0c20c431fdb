"""arm6_pick_place: the 6-DoF MuJoCo arm picks the box up with its suction cup and places it.

Run it with ``uv run openel-async run apps/arm6_pick_place.py [--realtime] [--duration S]
[--place X Y] [--out DIR] [--no-live]`` (``--help`` lists every option), or as
``uv run openel-async demo --app arm6``.  See docs/apps.md.

The application lives in the package (:mod:`openel_async.cli.arm6_pick_place`) so that an
installed wheel runs it too (``apps/`` is not shipped).  What it does, in short:

1. the simulation is built from a declarative description: the six joints of ``arm6`` and its
   ``suction`` adhesion actuator become OpenEL Actuators (the suction cup is an
   ``openel_mujoco`` effector: TORQUE = adhesion force in N, NO_EXCITE = off);
2. closed-form inverse kinematics with the tool pointing down (``Arm6Kinematics``) gives every
   target, solved and planned before anything moves;
3. an ``AxisGroup`` moves the six joints together (home -> above the box -> down -> suction
   on -> lift -> over the place location -> down -> suction off -> up -> home), every motion
   time-synchronized on an ``EventTimer`` of the simulation clock;
4. at the end: a summary with the box's displacement, a PNG plot of the joints and PNG
   snapshots of the scene in ``out/arm6_pick_place/`` (``--out`` to change).
"""

from __future__ import annotations

from openel_async.cli.arm6_pick_place import (
    Arm6Kinematics,
    UnreachableError,
    main,
    plan_pick_place,
    run_pick_place,
)

__all__ = ["Arm6Kinematics", "UnreachableError", "main", "plan_pick_place", "run_pick_place"]
