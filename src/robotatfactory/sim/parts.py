"""The free-joint bookkeeping of part bodies (move, recolour, read poses)."""
from __future__ import annotations

import math

import numpy as np

from .scene import part_rgba, quat_yaw

class PartBodies:
    """Handles to the part bodies of a compiled model: ids, qpos/qvel addresses, visual geom ids."""

    def __init__(self, model, info):
        import mujoco

        self.model = model
        self.ids = sorted(info.parts)
        self.body = {}
        self.qadr = {}
        self.vadr = {}
        self.visual_geom = {}
        self.letter: dict[int, str] = {}
        for pid in self.ids:
            b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, info.parts[pid])
            j = model.body_jntadr[b]
            self.body[pid] = b
            self.qadr[pid] = int(model.jnt_qposadr[j])
            self.vadr[pid] = int(model.jnt_dofadr[j])
            self.visual_geom[pid] = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, info.part_visual_geoms[pid])
        self.body_to_part = {b: pid for pid, b in self.body.items()}

    def set_letter(self, pid: int, letter: str) -> None:
        self.letter[pid] = letter
        self.model.geom_rgba[self.visual_geom[pid]] = part_rgba(letter)

    def place(self, data, pid: int, x: float, y: float, facing: float, z: float = 0.0) -> None:
        """Teleport a part: footprint centre at (x, y) on the floor, plate towards ``facing``; at rest."""
        a = self.qadr[pid]
        data.qpos[a:a + 7] = (x, y, z, math.cos(facing / 2), 0.0, 0.0, math.sin(facing / 2))
        v = self.vadr[pid]
        data.qvel[v:v + 6] = 0.0

    def xy(self, data, pid: int) -> tuple[float, float]:
        a = self.qadr[pid]
        return float(data.qpos[a]), float(data.qpos[a + 1])

    def pose(self, data, pid: int) -> tuple[float, float, float]:
        """(x, y, facing) of a part from its free joint."""
        a = self.qadr[pid]
        return float(data.qpos[a]), float(data.qpos[a + 1]), quat_yaw(data.qpos[a + 3:a + 7])

    def all_xy(self, data) -> dict[int, tuple[float, float]]:
        return {pid: self.xy(data, pid) for pid in self.ids}

    def positions(self, data) -> np.ndarray:
        return np.array([data.qpos[self.qadr[p]:self.qadr[p] + 3] for p in self.ids])
