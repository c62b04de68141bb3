"""Offscreen rendering with MuJoCo's OpenGL renderer (EGL, headless) and SimTwo's camera frame format.

OpenGL hands back rows bottom-up in R G B order; SimTwo publishes B G R A bottom-up. So the wire frame is
one colour conversion away from what the GPU (here Mesa's llvmpipe) returns, and the top-row-first BGR image
OpenCV wants is one flip away.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from .scene import RENDER_GROUPS  # noqa: E402


@dataclass
class CameraFrame:
    """One rendered camera frame.

    ``index`` counts published frames from 0, ``tick`` is the 60 FPS render clock tick (``index *
    decimation``), ``tick_time`` the tick's time (s) and ``time`` the simulation time of the state drawn
    (the first physics step at or after the tick). ``rgb_bottom_up`` is the raw OpenGL read-out.
    """

    index: int
    tick: int
    tick_time: float
    time: float
    rgb_bottom_up: np.ndarray

    def bgr(self) -> np.ndarray:
        """Top-row-first BGR uint8 image, what ``decode_frame`` returns on the receiving side."""
        return cv2.cvtColor(np.ascontiguousarray(self.rgb_bottom_up[::-1]), cv2.COLOR_RGB2BGR)

    def wire(self, bottom_up: bool = True) -> np.ndarray:
        """SimTwo's ZMQ payload as an ``H x W x 4`` uint8 array (B G R A; rows bottom-up by default)."""
        src = self.rgb_bottom_up if bottom_up else np.ascontiguousarray(self.rgb_bottom_up[::-1])
        return cv2.cvtColor(src, cv2.COLOR_RGB2BGRA)


class Renderer:
    """Renders one fixed camera of a model into a reusable buffer.

    One OpenGL context per renderer; use it from one thread. ``close()`` frees it (also on garbage
    collection, but closing explicitly avoids EGL errors at interpreter exit).
    """

    def __init__(self, model, camera: str, width: int, height: int, groups=RENDER_GROUPS):
        import mujoco

        self._mj = mujoco
        self.model = model
        self.width, self.height = int(width), int(height)
        cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam_id < 0:
            raise ValueError(f"no camera {camera!r} in the model")
        self.gl = mujoco.GLContext(self.width, self.height)
        self.gl.make_current()
        self.con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_50)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.con)
        self.scene = mujoco.MjvScene(model, maxgeom=1000)
        for flag in ("mjRND_SHADOW", "mjRND_REFLECTION", "mjRND_SKYBOX", "mjRND_FOG", "mjRND_HAZE"):
            self.scene.flags[getattr(mujoco.mjtRndFlag, flag)] = 0
        self.opt = mujoco.MjvOption()
        self.opt.geomgroup[:] = np.asarray(groups, dtype=np.uint8)
        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self.cam.fixedcamid = cam_id
        self.rect = mujoco.MjrRect(0, 0, self.width, self.height)
        self.rgb = np.empty((self.height, self.width, 3), dtype=np.uint8)
        self._catmask = mujoco.mjtCatBit.mjCAT_ALL.value

    def render(self, data) -> np.ndarray:
        """Draw the present state; returns the internal RGB buffer, rows bottom-up (overwritten next call)."""
        mj = self._mj
        self.gl.make_current()
        mj.mjv_updateScene(self.model, data, self.opt, None, self.cam, self._catmask, self.scene)
        mj.mjr_render(self.rect, self.scene, self.con)
        mj.mjr_readPixels(self.rgb, None, self.rect, self.con)
        return self.rgb

    def render_bgr(self, data) -> np.ndarray:
        """Top-row-first BGR copy of the present state."""
        return cv2.cvtColor(np.ascontiguousarray(self.render(data)[::-1]), cv2.COLOR_RGB2BGR)

    def close(self) -> None:
        if getattr(self, "con", None) is not None:
            self.gl.make_current()
            self.con.free()
            self.con = None
        if getattr(self, "gl", None) is not None:
            self.gl.free()
            self.gl = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown: nothing left to report to
            pass
