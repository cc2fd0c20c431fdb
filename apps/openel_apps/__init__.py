"""The demo applications of openel-async, shipped in the same wheel as the framework and
registered under the ``openel_async.apps`` entry-point group (``openel-async demo --list``):

- ``arm2`` (:mod:`.arm2_square`): the 2-DoF MuJoCo arm traces a square;
- ``arm6`` (:mod:`.arm6_pick_place`): the 6-DoF MuJoCo arm picks and places a box;
- ``twoaxis`` (:mod:`.twoaxis`): the spec's two-axis synchronized demo on ``openel_sim`` motors
  or simulated CAN drives (:mod:`.can_rig`);
- ``pantilt`` (:mod:`.pan_tilt`): an RT component described by an RTC Profile.

Importing this package, or any app's entry point, imports no driver: each app imports its
drivers when it runs. docs/apps.md says how to write and register an app.
"""
