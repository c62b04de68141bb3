"""Sensors with SimTwo's semantics: encoders, the 2D ranger (LIDAR) and ray helpers.

* :class:`Encoder`: SimTwo's ``GetAxisOdo``: ticks since the previous control cycle, the floor of the
  accumulated fraction with the remainder carried to the next cycle, plus the running total.
* :class:`Lidar`: ``ranger2d``: N rays from -fov/2 to +fov/2 (step fov/(N-1)), distance to the nearest hit
  or -1 when nothing is within range, Gaussian noise sigma = a*exp(b*d) from a seeded generator. By default
  (``update="sweep"``) exactly SimTwo's schedule: rays measured a few at a time over the period, the values
  a script reads replaced all at once once per period, 0 before the first sweep (see the class docstring);
  ``update="per_ray"`` is the older idealisation (each ray's value replaced as soon as it is measured).
"""
from __future__ import annotations

import math

import numpy as np

from ..robot import LidarSpec


class Encoder:
    """One wheel's encoder. ``update(angle)`` with the wheel's total angle (rad) once per control cycle."""

    __slots__ = ("ticks_per_rad", "last_angle", "fraction", "total", "delta")

    def __init__(self, ticks_per_rev: int, angle0: float = 0.0):
        self.ticks_per_rad = ticks_per_rev / (2 * math.pi)
        self.last_angle = angle0
        self.fraction = 0.0  # ticks accumulated but not yet reported, in [0, 1)
        self.total = 0
        self.delta = 0

    def update(self, angle: float) -> int:
        acc = self.fraction + (angle - self.last_angle) * self.ticks_per_rad
        self.last_angle = angle
        d = math.floor(acc)
        self.fraction = acc - d
        self.delta = int(d)
        self.total += self.delta
        return self.delta


def simtwo_ray_steps(rays: int, period: float, dt: float) -> list[int]:
    """For each ray of a SimTwo ``ranger2d``, the physics step within a sweep (0 = the sweep's first,
    ``period/dt - 1`` the last) at which SimTwo measures it for the last time, i.e. the measurement that
    the sweep reports.

    ``TSensor.PreProcess`` (ODERobots.pas 1593-1624) enables, before each physics step, the rays
    ``first .. first + active`` with ``first = round(N * TimeFromLastMeasure / Period)`` and
    ``active = round(N * dt / Period) + 1``, and resets them to -1; the collision of that step measures them.
    For 360 rays, 0.2 s and 1 ms: ray i is last measured at step max{j : round(1.8 j) <= i}, ray 0 at 0,
    ray 359 at 199. Rounding is Pascal's (and Python's) round half to even.
    """
    n_steps = int(round(period / dt))
    active = round(rays * dt / period) + 1
    last = [0] * rays
    for j in range(n_steps):
        first = round(rays * (j * dt) / period)
        for i in range(first, min(first + active, rays - 1) + 1):
            last[i] = j
    return last


class Lidar:
    """The ranger's schedule, pose log and ray casting against a MuJoCo model.

    The simulator calls :meth:`plan` at the start of a control cycle (after which physics steps of the
    cycle to log the robot's pose), :meth:`log_pose` after each of those steps, and :meth:`cast` at the end
    of the cycle, which measures the rays from the logged poses (``mj_ray``, each from its own pose) and
    applies the sweep updates that fell in the cycle, in order. ``ranges`` is what SimTwo's
    ``GetSensorValues`` returns at the end of the cycle.

    **SimTwo's schedule** (``update="sweep"``, the default; Viewer.pas 5416-5455, ODERobots.pas 1593-1624
    and 1842-1846). Each physics iteration SimTwo (1) enables a few rays (:func:`simtwo_ray_steps`), which
    are reset to -1 and measured by that iteration's collision (``dSpaceCollide`` before ``dWorldStep``,
    Viewer.pas 4370-4383), i.e. from the pose at the start of the step; (2) steps the physics; (3) adds dt to
    the sensor's ``TimeFromLastMeasure`` and, when it exceeds ``Period``, subtracts ``Period`` and copies
    every ray's last measure into the values at once (``UpdateMeasures``). The values start at 0
    (``TSensorMeasure`` fields, never written before the first update); no return within the beam's length
    is -1. The stand-in repeats this with the same double arithmetic, mapped onto its own clock so that
    SimTwo's phase between script calls and sweep updates is kept: SimTwo's first script call comes after 39
    physics steps (``SecondsCount > DecPeriod``, Viewer.pas 5228-5230), which the stand-in calls t = 40 ms,
    so stand-in step s is SimTwo's step s - 1.

    **When a sweep is taken, against the SensorFrames' Tms** (0.2 s, 360 rays, 1 ms steps, 40 ms cycles):
    sweep m = 1, 2, ... is published (values replaced) after the physics step ending at 200*m + 1 ms, i.e.
    1 ms after the frame with Tms = 200*m. The first frame that carries it has Tms_new = 200*m + 40 and the
    same values stay in the next four frames (up to Tms = 200*m + 200). Ray i of that sweep was measured
    from the robot's pose at Tms_new - 239 + j_i ms, with j_i = ``simtwo_ray_steps(...)[i]`` in 0..199 (ray 0
    at Tms_new - 239 ms, ray 180 at about Tms_new - 139 ms, ray 359 at Tms_new - 40 ms). Frames before
    Tms = 240 carry all zeros. In SimTwo's own clock every instant is 1 ms earlier (its frames are at
    40*c + 39 ms); relative to the frames it is the same.

    ``update="per_ray"`` (idealisation): ray i of sweep s is measured at the first physics step at or after
    ``(s + i/N) * period`` and its value replaced at the end of that cycle; rays read -1 before their first
    measurement.

    **Self hits.** SimTwo's rays are ODE rays in the scene's one space attached to the base body: they hit
    every geom except those on that body (the robot's wheels are separate bodies, so they are hit). With
    ``self_groups`` the simulator passes the geom group of the robot's wheels; :meth:`measure_self_hits`
    casts each ray against them once in the robot's frame (the wheels are fixed relative to the base; only
    their spin changes, which does not change a cylinder) and :meth:`cast` takes, per ray, the nearer of the
    world hit (wheels excluded: the world is cast from logged poses while the wheels are at the end-of-cycle
    pose) and the wheel hit.
    """

    def __init__(self, spec: LidarSpec, physics_step: float, seed: int, noise: bool, groups,
                 update: str = "sweep", self_groups=None):
        if update not in ("sweep", "per_ray"):
            raise ValueError(f"lidar update {update!r}: expected 'sweep' or 'per_ray'")
        self.spec = spec
        self.update = update
        self.n = int(spec.rays)
        self.angles = spec.angles()
        self.sweep = update == "sweep"
        # what GetSensorValues returns; in per_ray mode the rays' measures themselves
        self.ranges = np.zeros(self.n) if self.sweep else np.full(self.n, -1.0)
        self._measures = np.full(self.n, -1.0) if self.sweep else self.ranges  # Rays[i].Measure.dist
        self.sweeps = 0  # sweeps published so far
        self.noise = bool(noise)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x11DA2]))
        self.geomgroup = np.asarray(groups, dtype=np.uint8)
        self.self_groups = None if self_groups is None else np.asarray(self_groups, dtype=np.uint8)
        self.self_hits: np.ndarray | None = None  # per ray: distance to the robot's own wheels, -1 = none
        self.bodyexclude = -1  # body id the rays never hit (several robots: the robot's own base), -1: none
        self._dt = float(physics_step)
        self._period = float(spec.period)
        # SimTwo's counters (sweep mode): TimeFromLastMeasure and the number of rays enabled per step
        self._t = 0.0
        self._active = round(self.n * self._dt / self._period) + 1
        # per_ray mode: rays due by the end of physics step k = floor(k * n * dt / period)
        self._dt_ns = int(round(physics_step * 1e9))
        self._period_ns = int(round(spec.period * 1e9))
        self._items: list | None = None
        self.poses: list = []
        self._pnt = np.zeros(3)
        self._vec = np.zeros(3)
        self._angles_list = self.angles.tolist()

    # ------------------------------------------------------------------------------------------ schedule
    def _window(self, t: float) -> range:
        first = round(self.n * t / self._period)
        return range(first, min(first + self._active, self.n - 1) + 1)

    def plan(self, first_step: int, nsteps: int) -> list[int]:
        """Which of the physics steps ``first_step+1 .. first_step+nsteps`` need the robot's pose logged;
        returns their cycle-relative indexes (0..nsteps-1), ascending."""
        items: list[tuple[int, list[int], bool]] = []  # (offset, rays measured there, sweep published first)
        if self.sweep:
            dt, period, n, active = self._dt, self._period, self.n, self._active
            last = n - 1
            # SimTwo's counter over this cycle's steps and one more (a ray's last measurement counts):
            # first enabled ray and whether the sweep is published first, per step
            t = self._t
            firsts, latches = [], []
            for j in range(nsteps + 1):
                latch = False
                if first_step + j + 1 >= 2:  # stand-in step s is SimTwo's s - 1: its counter starts later
                    t = t + dt
                    if t > period:
                        t = t - period
                        latch = True
                if j == nsteps - 1:
                    t_end = t
                firsts.append(round(n * t / period))
                latches.append(latch)
            self._t = t_end
            for j in range(nsteps):
                f = firsts[j]
                hi = f + active if f + active < last else last
                if not latches[j + 1] and firsts[j + 1] - 1 < hi:
                    hi = firsts[j + 1] - 1  # rays enabled again next step are measured again there
                if f <= hi or latches[j]:
                    items.append((j, list(range(f, hi + 1)), latches[j]))
        else:
            n, dtn, pn = self.n, self._dt_ns, self._period_ns
            prev = (first_step * n * dtn) // pn
            for j in range(nsteps):
                c = ((first_step + j + 1) * n * dtn) // pn
                if c > prev:
                    items.append((j, [r % n for r in range(prev, c)], False))
                prev = c
        self._items = [(rays, latch) for _, rays, latch in items]
        self.poses = [None] * len(items)
        return [j for j, _, _ in items]

    def log_pose(self, slot: int, x: float, y: float, yaw: float) -> None:
        """Log the robot's (x, y, yaw) after the ``slot``-th due step (the simulator's hot loop writes
        ``poses[slot] = qpos[free joint]`` as a 7-list instead: x, y, z, qw, qx, qy, qz)."""
        self.poses[slot] = (x, y, yaw)

    # ------------------------------------------------------------------------------------------ measuring
    def measure_self_hits(self, model, data, mujoco, body_pos, body_mat, own_geoms=None) -> None:
        """Cast every ray once against the robot's own wheels (``self_groups``) from the LIDAR's origin at
        the robot body's present pose (``body_pos`` 3, ``body_mat`` 3x3); stores ``self_hits``.
        ``own_geoms`` (a scene of several robots): the geom ids of this robot's wheels; hits on any other
        geom of those groups (another robot's wheels) are not self hits."""
        if self.self_groups is None:
            self.self_hits = None
            return
        R = np.asarray(body_mat, dtype=np.float64).reshape(3, 3)
        origin = np.asarray(body_pos, dtype=np.float64) + R @ np.asarray(self.spec.xyz, dtype=np.float64)
        out = np.full(self.n, -1.0)
        gid = np.zeros(1, dtype=np.int32) if own_geoms is not None else None
        for i, a in enumerate(self._angles_list):
            vec = np.ascontiguousarray(R @ np.array([math.cos(a), math.sin(a), 0.0]))
            d = mujoco.mj_ray(model, data, origin, vec, self.self_groups, 1, -1, gid)
            if gid is not None and int(gid[0]) not in own_geoms:
                continue
            if 0.0 <= d <= float(self.spec.range_max):
                out[i] = d
        self.self_hits = out

    def cast(self, model, data, mujoco) -> None:
        """Measure every ray due in this cycle and publish the sweeps that completed, in order."""
        items, self._items = self._items, None
        if not items:
            return
        angles = self._angles_list
        lx, ly, lz = self.spec.xyz
        pnt, vec = self._pnt, self._vec
        pnt[2] = lz
        gg = self.geomgroup
        bx = self.bodyexclude
        ray = mujoco.mj_ray
        cos, sin, atan2 = math.cos, math.sin, math.atan2
        idx: list[int] = []
        dist: list[float] = []
        # one mj_ray per ray from the pose logged at its physics step (mj_multiRay has a fixed cost of
        # ~10 us that only pays off for many rays from one point); no geom id asked: -1 means no hit
        for (rays, _), pose in zip(items, self.poses):
            if not rays:
                continue
            if len(pose) == 7:  # the free joint's qpos: yaw from the quaternion
                x, y, _, w, qx, qy, qz = pose
                yaw = atan2(2.0 * (w * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
            else:
                x, y, yaw = pose
            cy, sy = cos(yaw), sin(yaw)
            pnt[0] = x + cy * lx - sy * ly
            pnt[1] = y + sy * lx + cy * ly
            for i in rays:
                a = yaw + angles[i]
                vec[0] = cos(a)
                vec[1] = sin(a)
                dist.append(ray(model, data, pnt, vec, gg, 1, bx, None))
            idx.extend(rays)
        m = len(idx)
        if m:
            d = np.asarray(dist)
            rmax = float(self.spec.range_max)
            if self.self_hits is not None:
                s = self.self_hits[idx]
                d = np.where((s >= 0) & ((d < 0) | (d > rmax) | (s < d)), s, d)
            valid = (d >= 0) & (d <= rmax)
            if self.noise:
                z = self.rng.standard_normal(m)
                d = np.maximum(d + z * self.spec.noise_sigma(np.where(valid, d, 0.0)), 0.0)
            vals = np.where(valid, d, -1.0)
        k = 0
        meas = self._measures
        for rays, latch in items:
            if latch:
                self.ranges[:] = meas
                self.sweeps += 1
            if rays:
                meas[rays] = vals[k:k + len(rays)]
                k += len(rays)


def cast_ray(model, data, mujoco, origin, direction, groups, cutoff: float) -> tuple[float, int]:
    """Distance (m) and geom id of the first hit along a unit ``direction`` within ``cutoff``, or (-1, -1)."""
    gid = np.zeros(1, dtype=np.int32)
    d = mujoco.mj_ray(model, data, np.asarray(origin, dtype=np.float64), np.asarray(direction, dtype=np.float64),
                      np.asarray(groups, dtype=np.uint8), 1, -1, gid)
    if gid[0] < 0 or d < 0 or d > cutoff:
        return -1.0, -1
    return float(d), int(gid[0])
