"""Offscreen rendering with MuJoCo's OpenGL renderer (EGL, headless), SimTwo's camera frame format, and
when SimTwo renders (:class:`RenderCadence`).

OpenGL hands back rows bottom-up in R G B order; SimTwo publishes B G R A bottom-up. So the wire frame is
one colour conversion away from what the GPU (here Mesa's llvmpipe) returns, and the top-row-first BGR image
OpenCV wants is one flip away.

When SimTwo renders (read in ``P33a/SimTwo``, see docs/simulator.md): the GUI's ``TGLCadencer``
(``Viewer.lfm`` 1426-1435: ``FixedDeltaTime = 1/60``, ``Mode = cmApplicationIdle``, ``SleepLength = 1``)
calls ``GLCadencerProgress`` once for every whole 1/60 s of WALL time that has passed on its own grid
(several calls in a row to catch up after a slow iteration). Each call runs physics until ``physTime``
passes ``physTime + FixedDeltaTime * TimeFactor`` (``Viewer.pas`` 5211-5212): 17 steps of 1 ms
(``Ode_dt``, ``Viewer.pas`` 4240), the script every 40 of them (``DecPeriod``, 4246, 5228-5230). The viewers
repaint after the calls (``GLSceneViewer.Invalidate``, 5485), so a rendered frame shows the state at the
end of the LAST 17-step chunk; chunks run in a catch-up burst are never drawn. The camera form's
``PostRender`` (``cameras.pas`` 270-273) runs ``UpdateGLCameras``, which sends every ``decimation``-th
render (``RemoteImageDecimation``, ``cameras.pas`` 136-141; ``<frame decimation='4'/>`` in the scene's
``AGV.xml``). Rendered instants are therefore multiples of 17 ms of simulation time, but WHICH multiples
depends on the wall clock: the published frames are 68 ms apart while the GUI keeps up and 85, 102, ...
ms apart after a slow iteration, with no fixed phase to the 40 ms control cycle.
"""
from __future__ import annotations

import itertools
import math
import os
from dataclasses import dataclass, replace

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from .scene import RENDER_GROUPS  # noqa: E402


@dataclass
class CameraFrame:
    """One rendered camera frame.

    ``index`` counts published frames from 0; ``tick`` counts render ticks (GUI renders) since t = 0;
    ``time`` is the simulation time of the state drawn (s, a physics-step boundary). With
    ``camera_timing="grid"``, ``tick = index * decimation`` and ``tick_time = tick / 60`` s of simulation
    time (``time`` is the first physics step at or after it). With ``"simtwo"``, ``tick_time`` is the render's
    instant on the modelled GUI's wall clock (s since the loop started; see :class:`RenderCadence`).
    ``rgb_bottom_up`` is the raw OpenGL read-out.
    """

    index: int
    tick: int
    tick_time: float
    time: float
    rgb_bottom_up: np.ndarray
    wall: float = 0.0  # s: when the frame left the simulator on the render model's clock (grid: = tick_time)

    def bgr(self) -> np.ndarray:
        """Top-row-first BGR uint8 image, what ``decode_frame`` returns on the receiving side."""
        return cv2.cvtColor(np.ascontiguousarray(self.rgb_bottom_up[::-1]), cv2.COLOR_RGB2BGR)

    def wire(self, bottom_up: bool = True) -> np.ndarray:
        """SimTwo's ZMQ payload as an ``H x W x 4`` uint8 array (B G R A; rows bottom-up by default)."""
        src = self.rgb_bottom_up if bottom_up else np.ascontiguousarray(self.rgb_bottom_up[::-1])
        return cv2.cvtColor(src, cv2.COLOR_RGB2BGRA)


CAMERA_TIMINGS = ("simtwo", "grid")


@dataclass(frozen=True)
class GuiLoopModel:
    """Wall-clock costs of SimTwo's GUI loop (seconds of wall time), the random part of :class:`RenderCadence`.

    Not measured on a real SimTwo (none was available): plausible figures for a desktop PC. What matters for
    the receiver is the structure they produce (renders on chunk ends, catch-up bursts that skip renders,
    no phase lock to the control cycle), not the exact numbers.

    * ``poll``: one idle-loop turn without a progress (``Sleep(SleepLength = 1)`` plus message handling),
      plus an exponential extra of mean ``poll_jitter``;
    * ``physics_per_step``: wall time of one 1 ms physics step (ODE, a robot and a dozen obstacles);
    * ``render``: median wall time of one repaint (main viewer, camera viewer, 640x480 snapshot, pixel swap,
      ZMQ send), log-normal with ``render_sigma``;
    * ``hiccup_prob``/``hiccup_max``: chance per repaint of an extra stall, uniform up to ``hiccup_max``
      (other windows, the OS); a stall longer than one 1/60 s tick makes the cadencer catch up.
    """

    poll: float = 0.001
    poll_jitter: float = 0.0005
    physics_per_step: float = 0.0001
    render: float = 0.006
    render_sigma: float = 0.3
    hiccup_prob: float = 0.04
    hiccup_max: float = 0.045


@dataclass(frozen=True)
class ScheduledFrame:
    """A published camera frame's place in time: render the state after physics step ``step``."""

    index: int  # published frames since t = 0
    tick: int  # GUI renders since t = 0 (this one included; grid: index * decimation)
    tick_time: float  # s: grid: tick / fps of simulation time; simtwo: the render on the model's wall clock
    step: int  # physics steps since t = 0 whose end state the frame shows
    wall: float  # s: when the frame is sent, on the model's wall clock (grid: = tick_time)


@dataclass(frozen=True)
class GuiIteration:
    """One turn of SimTwo's GUI loop that advanced physics (``mode="simtwo"``), on the model's wall clock.

    Physics steps ``first_step + 1 .. first_step + steps`` ran from ``start`` on (``physics_per_step`` each;
    the script call for ``Tms = 40 k`` runs before the step after it, so in the iteration with ``first_step <=
    40 k < first_step + steps``), then one render showing step ``first_step + steps`` finished at ``sent``;
    ``frame`` is the published frame when this render was a ``decimation``-th one.
    """

    start: float
    first_step: int
    steps: int
    sent: float
    frame: ScheduledFrame | None


class RenderCadence:
    """When the stand-in renders and publishes camera frames (deterministic for a seed).

    ``mode="grid"`` (the idealisation): frame ``j`` shows the first physics step at or after
    ``j * decimation / fps`` s of simulation time (15 frames per simulation second, k/15 s).

    ``mode="simtwo"`` (the default of ``raf sim``): SimTwo's GUI loop, module docstring. A seeded virtual wall
    clock runs the cadencer: each idle turn costs ``poll``; when ``n >= 1`` whole ``1/fps`` wall ticks have
    passed since the cadencer's last tick, ``n`` chunks of ``chunk_steps`` physics steps are run (``chunk_steps``
    is the smallest step count whose time reaches ``1/fps``: 17 at 1 ms), then one render shows the state
    after the last chunk, and every ``decimation``-th render is published. ``frames()`` yields the published
    frames in order, ``iterations()`` the GUI turns (for the emission times of a SimTwo-like stream); both
    depend on the seed only, never on simulation results.
    """

    def __init__(self, mode: str, dt: float, fps: float = 60.0, decimation: int = 4, seed: int = 0,
                 gui: GuiLoopModel | None = None):
        from ..errors import ConfigError

        if mode not in CAMERA_TIMINGS:
            raise ConfigError(f"camera timing {mode!r}: choose one of {', '.join(CAMERA_TIMINGS)}")
        if not (dt > 0 and fps > 0 and decimation >= 1):
            raise ConfigError(f"camera cadence: dt {dt}, fps {fps} must be > 0 and decimation {decimation} >= 1")
        self.mode, self.dt, self.fps, self.decimation = mode, float(dt), float(fps), int(decimation)
        self.seed = int(seed)
        self.gui = gui or GuiLoopModel()
        self.tick_period = 1.0 / self.fps
        # SimTwo: `while physTime < physTime0 + FixedDeltaTime do step` (Viewer.pas 5211-5212)
        self.chunk_steps = max(1, math.ceil(self.tick_period / self.dt - 1e-9))

    def frames(self):
        """The published frames, in order (a fresh endless iterator)."""
        if self.mode == "grid":
            return self._grid()
        return (it.frame for it in self.iterations() if it.frame is not None)

    def _grid(self):
        j = 0
        period = self.decimation / self.fps
        while True:
            t = j * period
            yield ScheduledFrame(j, j * self.decimation, t, math.ceil(t / self.dt - 1e-6), t)
            j += 1

    def iterations(self):
        """The GUI turns that ran physics, in order (a fresh endless iterator; ``mode="simtwo"`` only)."""
        import numpy as np

        if self.mode != "simtwo":
            raise ValueError("iterations() models SimTwo's GUI loop: mode='simtwo' only")
        g, tick = self.gui, self.tick_period
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0xCA3E7A]))
        wall = 0.0  # the model's wall clock (s since the cadencer was enabled)
        last = 0.0  # TGLCadencer's lastTime: advances by whole ticks
        steps = renders = published = 0
        while True:
            wall += g.poll + rng.exponential(g.poll_jitter)
            n = math.floor((wall - last) / tick + 1e-12)
            if n < 1:
                continue
            last += n * tick
            start, first, k = wall, steps, n * self.chunk_steps
            steps += k
            wall += k * g.physics_per_step
            wall += g.render * math.exp(g.render_sigma * rng.standard_normal())
            sent = wall
            if rng.random() < g.hiccup_prob:
                wall += rng.uniform(0.0, g.hiccup_max)
            renders += 1
            frame = None
            if renders % self.decimation == 0:
                frame = ScheduledFrame(published, renders, sent, steps, sent)
                published += 1
            yield GuiIteration(start, first, k, sent, frame)


def one_in(frames, n: int):
    """Every ``n``-th of the scheduled ``frames`` (the first, the ``n+1``-th, ...), numbered on from 0 as
    published frames are (``SimConfig.camera_every``: a slower host's SimTwo; ``n`` 1: all of them)."""
    if n == 1:
        return frames
    return (replace(f, index=j) for j, f in enumerate(itertools.islice(frames, 0, None, n)))


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
