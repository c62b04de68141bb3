"""Sensors with SimTwo's semantics: encoders, the 2D ranger (LIDAR) and ray helpers.

* :class:`Encoder`: SimTwo's ``GetAxisOdo``: ticks since the previous control cycle, the floor of the
  accumulated fraction with the remainder carried to the next cycle, plus the running total.
* :class:`Lidar`: ``ranger2d``: N rays from -fov/2 to +fov/2 (step fov/(N-1)), distance to the nearest hit
  or -1 when nothing is within range, Gaussian noise sigma = a*exp(b*d) from a seeded generator, rays
  refreshed in turn over the sweep period (ray ``i`` of sweep ``s`` is measured at the first physics step at
  or after ``(s + i/N) * period``, from the pose the robot had then).
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


class Lidar:
    """The ranger's schedule, pose log and ray casting against a MuJoCo model.

    The simulator calls :meth:`plan` at the start of a control cycle (which physics steps of the cycle
    have rays due), :meth:`log_pose` after each of those steps, and :meth:`cast` at the end of the cycle.
    Rays are cast at the end of the cycle from the logged poses (``mj_ray``, each from its own pose):
    the robot's own geoms are excluded by group, and the rest of the world does not move within a cycle
    except parts being pushed (sub-millimetre).
    """

    def __init__(self, spec: LidarSpec, physics_step: float, seed: int, noise: bool, groups):
        self.spec = spec
        self.n = int(spec.rays)
        self.angles = spec.angles()
        self.ranges = np.full(self.n, -1.0)
        self.noise = bool(noise)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x11DA2]))
        self.geomgroup = np.asarray(groups, dtype=np.uint8)
        self.rays_cast = 0
        # integer schedule: rays due by the end of physics step k = floor(k * n * dt / period)
        self._dt_ns = int(round(physics_step * 1e9))
        self._period_ns = int(round(spec.period * 1e9))
        self._plans: dict[tuple[int, int], tuple] = {}
        self._plan = None
        self.poses: list = []
        self._gid1 = np.zeros(1, dtype=np.int32)
        self._pnt = np.zeros(3)
        self._vec = np.zeros(3)
        self._angles_list = self.angles.tolist()

    def _count(self, step: int) -> int:
        return (step * self.n * self._dt_ns) // self._period_ns

    def plan(self, first_step: int, nsteps: int) -> list[int]:
        """Which of the physics steps ``first_step+1 .. first_step+nsteps`` have rays due; returns their
        cycle-relative indexes (0..nsteps-1), after which the simulator logs the pose."""
        # the schedule repeats every sweep period: cache it by the phase within the sweep
        steps_per_sweep = self._period_ns // self._dt_ns if self._period_ns % self._dt_ns == 0 else None
        key = (first_step % steps_per_sweep if steps_per_sweep else first_step, nsteps)
        p = self._plans.get(key)
        if p is None or not steps_per_sweep:
            due_steps, counts, rays = [], [], []
            prev = self._count(first_step)
            for j in range(nsteps):
                c = self._count(first_step + j + 1)
                if c > prev:
                    due_steps.append(j)
                    counts.append(c - prev)
                    rays.extend(range(prev, c))
                prev = c
            # ray counters relative to the cycle's first ray, so the cached plan holds at any sweep
            base = self._count(first_step)
            rel = np.asarray(rays, dtype=np.int64) - base
            group = np.repeat(np.arange(len(counts)), counts)
            bounds = np.concatenate([[0], np.cumsum(counts)]).astype(int).tolist()
            p = (due_steps, rel, group, bounds)
            if steps_per_sweep:
                self._plans[key] = p
        self._plan = (p, self._count(first_step))
        self.poses = [None] * len(p[0])
        return p[0]

    def log_pose(self, slot: int, x: float, y: float, yaw: float) -> None:
        """Log the robot's (x, y, yaw) after the ``slot``-th due step (the simulator's hot loop writes
        ``poses[slot] = qpos[free joint]`` as a 7-list instead: x, y, z, qw, qx, qy, qz)."""
        self.poses[slot] = (x, y, yaw)

    def cast(self, model, data, mujoco) -> None:
        """Measure every ray due in this cycle."""
        if self._plan is None:
            return
        (due_steps, rel, group, bounds), base = self._plan
        self._plan = None
        m = len(rel)
        if m == 0:
            return
        idx = ((rel + base) % self.n).tolist()
        angles = self._angles_list
        lx, ly, lz = self.spec.xyz
        pnt, vec = self._pnt, self._vec
        pnt[2] = lz
        gg = self.geomgroup
        ray = mujoco.mj_ray
        cos, sin, atan2 = math.cos, math.sin, math.atan2
        dist = [0.0] * m
        # one mj_ray per ray from the pose logged at its physics step (mj_multiRay has a fixed cost of
        # ~10 us that only pays off for many rays from one point); no geom id asked: -1 means no hit
        for g, pose in enumerate(self.poses):
            if len(pose) == 7:  # the free joint's qpos: yaw from the quaternion
                x, y, _, w, qx, qy, qz = pose
                yaw = atan2(2.0 * (w * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
            else:
                x, y, yaw = pose
            cy, sy = cos(yaw), sin(yaw)
            pnt[0] = x + cy * lx - sy * ly
            pnt[1] = y + sy * lx + cy * ly
            for r in range(bounds[g], bounds[g + 1]):
                a = yaw + angles[idx[r]]
                vec[0] = cos(a)
                vec[1] = sin(a)
                dist[r] = ray(model, data, pnt, vec, gg, 1, -1, None)
        dist = np.asarray(dist)
        rmax = float(self.spec.range_max)
        valid = (dist >= 0) & (dist <= rmax)
        if self.noise:
            z = self.rng.standard_normal(m)
            dist = np.maximum(dist + z * self.spec.noise_sigma(np.where(valid, dist, 0.0)), 0.0)
        self.ranges[idx] = np.where(valid, dist, -1.0)
        self.rays_cast += m


def cast_ray(model, data, mujoco, origin, direction, groups, cutoff: float) -> tuple[float, int]:
    """Distance (m) and geom id of the first hit along a unit ``direction`` within ``cutoff``, or (-1, -1)."""
    gid = np.zeros(1, dtype=np.int32)
    d = mujoco.mj_ray(model, data, np.asarray(origin, dtype=np.float64), np.asarray(direction, dtype=np.float64),
                      np.asarray(groups, dtype=np.uint8), 1, -1, gid)
    if gid[0] < 0 or d < 0 or d > cutoff:
        return -1.0, -1
    return float(d), int(gid[0])
