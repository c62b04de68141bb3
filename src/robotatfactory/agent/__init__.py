"""The autonomous competition robot's core (issue 11): plain Python, no ROS import.

Each module has one job and is usable and testable alone:

* :mod:`.client` -- the factory-state server client (UDP): PING until PONG, IWP until it is not STOP, then
  OWP/MAP/MBP/CTL; timeouts, retries, strict parsing.
* :mod:`.state` -- the factory as the server spells it (:class:`FactoryState`) and slot references.
* :mod:`.tasks` -- the round's task logic: which part goes where next, and the whole round's plan.
* :mod:`.delay` -- learns the machines' processing delay from what the server shows.
* :mod:`.footprint` -- the robot's outline (m, base_link frame) and the docking geometry of a slot.
* :mod:`.obstacles` -- walls, ribs, parts and the floor's edge: exact polygons and a clearance grid.
* :mod:`.planner` -- collision-free paths on the field map for the robot's footprint (grid A*, smoothed).
* :mod:`.smooth` -- a polyline's corners rounded into arcs, and the pieces a follower drives.
* :mod:`.hybrid` -- paths of forward arcs and straight reversing, for carrying on SimTwo's magnet.
* :mod:`.legs` -- a leg to a slot (carrying or not) planned, timed, or why it cannot be.
* :mod:`.follower` -- a path follower on the pose estimate with a speed profile and acceleration limits.
* :mod:`.docking` -- the final approach: pick with the contact switch and the magnet, place, back out.
* :mod:`.predict` -- a pose estimate brought forward to now (the estimate's age at constant speeds).
* :mod:`.recovery` -- the pose's uncertainty, re-localizing, and telling a stuck robot.
* :mod:`.settings` -- every setting of the agent and its node, once (:class:`AgentSettings`).
* :mod:`.behaviour` -- the round's per-cycle state machine tying them together (:class:`RoundAgent`).

docs/agent.md describes the decisions and what was measured.

Frames: the field (map/world) frame of :mod:`robotatfactory.field`; base_link on the floor between the
wheels, x forward. Units: metres, radians, seconds.
"""
