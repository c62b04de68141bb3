"""SimTwo's electromagnet as a force (``SimConfig.magnet="force"``, the default).

What SimTwo computes (repository ``P33a/SimTwo`` at 90afa72; the RobotFactoryPro2022 scene):

* The electromagnet is a ``<solenoid>`` sensor of ``AGV.xml`` (lines 197-205): one ODE ray
  (``CreateOneRaySensor``, Viewer.pas 2978-2981) of ``beam length='0.02'`` placed at
  ``x = RobotLength/2 + 0.01`` on the base plate, pointing forward, i.e. from the centre of the solenoid's
  shell (AGV.xml 89-96: a cylinder of radius 0.015 m and length 0.01 m, ``surface mu='0.1'``), 5 mm behind its
  front face. ``<force fmax='10' k2='0.5'/>`` (read at Viewer.pas 2894-2898; defaults fmax 1, k1 0, k2 1 at
  2836); the sensor's period is the default 0.01 s (2833, no ``<period>`` in AGV.xml).
* Every physics step (Viewer.pas 5414-5455): ``PreProcess`` resets the ray, ``WorldUpdate`` collides the ray
  with the scene from the pose before the step (``nearCallback`` 374-408 keeps the nearest hit of any geom not
  on the robot's base body: ``dist``, hit point ``pos``, ``HitSolid``) and steps ODE, then ``PostProcess``
  (ODERobots.pas 1628-1653): if the sensor's value is > 0 and the hit solid has a body,
  ``f = 0.5 * Vin * Fmax / (1 + max(0, dist) * k2)^2`` along ``SensorPos - HitPos`` (the ray origin after the
  step minus the hit point before it, normalised) is *set* as the hit body's force (``TSolid.SetForce`` =
  ``dBodySetForce``, ODERobots.pas 1029-1032: at the body's centre of mass, no torque) and its opposite as
  the robot base's (``dBodySetForce``): ODE applies both during the next step. Every ``Period`` (0.01 s,
  ``TimeFromLastMeasure``, Viewer.pas 5448-5452) ``UpdateMeasures`` (ODERobots.pas 1849-1860) sets the value:
  1 if the ray's nearest hit is a solid marked ``<ferromagnetic/>``, else 0.
* ``Vin`` is set by the script's ``SetSensorVin`` (ODERobotsPublished.pas 1130-1133, a byte; the scene's
  control.pas uses 1 for on, line 345). Ferromagnetic in the scene: the parts' ``Plate`` shell (Parts.xml,
  PartRed/Green/Blue.xml: 80 x 5 x 23 mm, ``<ferromagnetic/>``, Parts.xml 55-63), nothing else.

So with Vin = 1 the pull is 5 N at the ray's origin and 4.95 N at its far end (2 cm): a finite force towards
the robot, at the part's centre of mass, from a single ray on the robot's centre line. Nothing else holds
the part: contact friction at the magnet's face and the floor's friction under the part decide whether it
stays in a turn or a collision.

The stand-in repeats this step by step with the same double arithmetic for the 10 ms counter (stand-in step
s is SimTwo's step s - 1, as for the LIDAR, :class:`~robotatfactory.sim.sensors.Lidar`): :meth:`pre_step`
casts the ray from the state before a step (``mj_ray`` against walls, other robots, part bodies and plates:
the nearest of them wins, as ODE's ray), :meth:`post_step` computes the force from that measure and the
ray's origin after the step and puts it in ``xfrc_applied`` (part and robot base, at their centres of mass)
for the next step. Units: metres, newtons, seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class MagnetParams:
    """The electromagnet of ``robot.electromagnet`` (data/robot_simtwo.json).

    ``x``: the magnet's front face (m ahead of base_link); ``ray_behind_face``: the ray starts this far behind
    it (SimTwo: at the solenoid shell's centre, 5 mm); ``beam``: the ray's length (m); ``fmax`` (N), ``k2``
    (1/m): SimTwo's force law; ``vin_on``: SetSensorVin's value for "on"; ``period``: the sensor's period (s),
    how often the ferromagnetic test is refreshed; ``mu``: friction of the magnet's face (SimTwo's solenoid
    shell ``surface mu``)."""

    x: float
    beam: float
    ray_behind_face: float = 0.005
    fmax: float = 10.0
    k2: float = 0.5
    vin_on: float = 1.0
    period: float = 0.01
    mu: float = 0.1

    @classmethod
    def from_spec(cls, em: dict) -> "MagnetParams":
        """From the robot file's ``electromagnet`` section (``x`` and ``beam`` required; the rest default as
        above, the defaults written once)."""
        return cls(**{f.name: float(em[f.name]) for f in fields(cls) if f.name in em or f.name in ("x", "beam")})

    def force(self, vin: float, dist: float) -> float:
        """SimTwo's magnitude (N) at ray distance ``dist`` (m): ``0.5 Vin Fmax / (1 + max(0, dist) k2)^2``."""
        return 0.5 * vin * self.fmax / (1.0 + max(0.0, dist) * self.k2) ** 2


class MagnetForce:
    """One robot's electromagnet as SimTwo's force (see the module docstring).

    ``vin``: the voltage in force (0 = off); ``value``: the sensor's value (1 = the ray's nearest hit was a
    ferromagnetic plate at the last 10 ms update); ``pulled``: the part id the force acts on in the coming
    step (None: none); ``last_force``: that force (N, world frame); ``dist``: the last ray distance (m, -1 =
    no hit within the beam).

    ``plate_geoms`` / ``part_geoms``: geom id -> part id for the parts' plates (ferromagnetic) and bodies (not);
    ``part_bodies``: part id -> body id (the free body the force acts on); ``robot_body``: the robot's base
    body; ``groups``: the geom groups the ray sees; ``bodyexclude``: a body the ray never hits (several robots:
    the own base; -1 none)."""

    def __init__(self, params: MagnetParams, model, data, mujoco, robot_body: int, z: float,
                 plate_geoms: dict[int, int], part_geoms: dict[int, int], part_bodies: dict[int, int],
                 groups, dt: float, bodyexclude: int = -1):
        self.p = params
        self.model, self.data, self._mj = model, data, mujoco
        self.robot_body = robot_body
        self.plate_geoms, self.part_geoms, self.part_bodies = plate_geoms, part_geoms, part_bodies
        self.groups = np.asarray(groups, dtype=np.uint8)
        self.bodyexclude = bodyexclude
        self.dt = float(dt)
        self._ol = (params.x - params.ray_behind_face, 0.0, float(z))  # the ray's origin in the robot's frame
        self._gid = np.zeros(1, dtype=np.int32)
        self._pnt, self._vec = np.zeros(3), np.zeros(3)
        self.vin = 0.0
        self.value = 0  # TSensor.Measures[0].value (refreshed every period)
        self._t = 0.0  # TimeFromLastMeasure
        # the ray's measure (from the state before the coming/last step): hit part id or None, ferromagnetic?,
        # distance, hit point (world); None: not measured for that step
        self._m: tuple | None = None
        self.dist = -1.0
        self.pulled: int | None = None
        self.last_force = np.zeros(3)
        self._set_on: int | None = None  # body whose xfrc_applied this magnet set (cleared next step)

    # ------------------------------------------------------------------------------------------ state
    @property
    def engaged(self) -> bool:
        """True when the steps must run :meth:`pre_step`/:meth:`post_step` (on, or a force still pending)."""
        return self.vin > 0.0 or self._set_on is not None

    def _origin(self) -> tuple[float, float, float]:
        """The ray's origin in the world now (plain floats: this runs twice per physics step while on)."""
        d, b = self.data, self.robot_body
        p, R = d.xpos[b], d.xmat[b]
        ox, _, oz = self._ol
        return (float(p[0] + R[0] * ox + R[2] * oz), float(p[1] + R[3] * ox + R[5] * oz),
                float(p[2] + R[6] * ox + R[8] * oz))

    def origin_dir(self):
        """(origin, direction) of the ray in the world now, as arrays."""
        R = self.data.xmat[self.robot_body]
        return np.array(self._origin()), np.array((R[0], R[3], R[6]))

    def measure(self) -> None:
        """Cast the ray from the present state (SimTwo's collision before a step)."""
        R = self.data.xmat[self.robot_body]
        o, v = self._pnt, self._vec
        o[0], o[1], o[2] = self._origin()
        v[0], v[1], v[2] = R[0], R[3], R[6]
        dist = self._mj.mj_ray(self.model, self.data, o, v, self.groups, 1, self.bodyexclude, self._gid)
        gid = int(self._gid[0])
        if gid < 0 or not 0.0 <= dist <= self.p.beam:
            self._m = (None, False, -1.0, None)
            return
        pid = self.plate_geoms.get(gid)
        ferro = pid is not None
        if pid is None:
            pid = self.part_geoms.get(gid)  # a part's body: hit, not ferromagnetic (None: a wall, a robot)
        self._m = (pid, ferro, float(dist), (o[0] + dist * v[0], o[1] + dist * v[1], o[2] + dist * v[2]))

    def _tick(self, s: int) -> bool:
        """SimTwo's TimeFromLastMeasure after stand-in step ``s`` (1-based); True when the value refreshes."""
        if s < 2:  # stand-in step s is SimTwo's s - 1
            return False
        self._t = self._t + self.dt
        if self._t > self.p.period:
            self._t = self._t - self.p.period
            return True
        return False

    def plan(self, s0: int, n: int) -> tuple[bool, int | None]:
        """At the start of a cycle of ``n`` steps after stand-in step ``s0``: ``(engaged, j)``. Engaged (on,
        or a force still pending): the caller runs :meth:`pre_step` before and :meth:`post_step` after every
        step. Otherwise nothing acts and only the value's refreshes matter: the counter is advanced over the
        whole cycle here, and the last refresh's ray (from the state before that step) is measured now
        (``j`` None) or by :meth:`idle_measure` after the cycle's step offset ``j`` (0-based)."""
        if self.engaged:
            return True, None
        last = None
        for k in range(s0 + 1, s0 + n + 1):
            if self._tick(k):
                last = k
        if last is None:
            return False, None
        if last == s0 + 1:
            self.idle_measure()
            return False, None
        return False, last - s0 - 2

    def idle_measure(self) -> None:
        """The value's refresh while idle: the ray from the present state, ferromagnetic or not."""
        self.measure()
        pid, ferro, dist, _ = self._m
        self.value = 1 if (pid is not None and ferro) else 0
        self.dist = dist
        self._m = None

    # ------------------------------------------------------------------------------------------ per step
    def pre_step(self) -> None:
        """Before a physics step: the ray's measure from the present state."""
        self.measure()

    def clear(self) -> None:
        """The accumulators ODE cleared in the step just taken: forget the force this magnet had set."""
        b = self._set_on
        if b is not None:
            self.data.xfrc_applied[b, :3] = 0.0
            self.data.xfrc_applied[self.robot_body, :3] = 0.0
            self._set_on = None
            self.pulled = None
            self.last_force = np.zeros(3)

    def post_step(self, s: int, clear: bool = True) -> None:
        """After stand-in physics step ``s``: PostProcess (the force for the next step) and, every period,
        UpdateMeasures (the value). ``clear=False``: the caller has already cleared every magnet's force
        (several robots: one magnet must not clear a force another set in the same step)."""
        if clear:
            self.clear()
        m = self._m
        if m is None:  # not measured before this step (e.g. switched on): measure now, as SimTwo would have
            self.measure()
            m = self._m
        pid, ferro, dist, hit = m
        self.dist = dist
        if self.value > 0 and pid is not None and self.vin > 0.0:  # (Vin = 0 sets a zero force: none)
            ox, oy, oz = self._origin()  # SensorPos after the step; the hit point is from before it
            vx, vy, vz = ox - hit[0], oy - hit[1], oz - hit[2]
            f = self.p.force(self.vin, dist)
            n = math.sqrt(vx * vx + vy * vy + vz * vz)
            if n > 0:
                f = f / n
            vec = np.array((vx * f, vy * f, vz * f))
            b = self.part_bodies[pid]
            self.data.xfrc_applied[b, :3] = vec
            self.data.xfrc_applied[self.robot_body, :3] = -vec
            self._set_on = b
            self.pulled = pid
            self.last_force = vec
        if self._tick(s):
            self.value = 1 if (pid is not None and ferro) else 0
        self._m = None

    def release(self) -> None:
        """Forget any pending force (the robot or the part was teleported)."""
        self.clear()
        self._m = None
