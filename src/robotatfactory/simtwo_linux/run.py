"""Run the real SimTwo headless: ``raf simtwo run``.

One :class:`SimTwoRun` is one SimTwo with everything it needs and nothing shared with another run:

- a fresh copy of the scene with the project's side installed (:mod:`.scene`) in a private folder, with a
  robot file's camera when ``robot_camera`` is given (``raf simtwo run --robot FILE``);
- its own X server (Xvfb, which picks a free display itself: ``-displayfd``) at 96 dpi, Windows' default,
  so that LCL does not rescale the forms (the camera's viewer must stay 640 x 480); Mesa renders in software;
- its own ports: SimTwo's UDP port (the scene's ``config_Params.ini``), the bridge's port (``control.pas``)
  and the camera's (``SIMTWO_CAMERA_PORT``, patch 10);
- ready when the script reports that it streams (``ready_line``: control.pas prints ``raf: streaming to ...``
  at the end of ``Initialize``, and ``Control`` sends the first SensorFrame right after it in the same script
  call); the bridge's port is not read, so that a bridge started at the same time can bind it. SimTwo's own
  messages (script compile and run errors, patch 11) end the wait at once and are in the error;
- the camera: SimTwo publishes frames only while its Cameras window is open, and no setting opens it. The
  run presses Ctrl+A in the viewer (``TFViewer.FormKeyDown``: the Cameras menu item), as a person would,
  with xdotool, and waits for a whole frame on the camera's port;
- :meth:`SimTwoRun.stop` (also on exit, Ctrl-C, and when this process dies: ``PR_SET_PDEATHSIG``) ends
  SimTwo and its X server and removes the folder.
"""
from __future__ import annotations

import ctypes
import os
import re
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..proc import free_port, stop_process
from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SIMTWO_UDP_PORT
from .build import Build
from .scene import DEFAULT_SCENE, HOT_CPU, SceneSettings, install

#: the virtual screen: wide enough for the Cameras window beside the others (scene.CAMERAS_WINDOW)
SCREEN = "2400x1200x24"
CAMERA_FRAME_BYTES = 640 * 480 * 4
READY_LINE = "script: raf: streaming to"  # control.pas's Initialize, right before its first SensorFrame
ERROR_RE = re.compile(r"^SimTwo: .*(\[Error\]|Error while executing|Exception while executing)")


class SimTwoError(RuntimeError):
    """SimTwo did not come up (or died): the message has its own last words."""


@dataclass
class Ports:
    udp: int = SIMTWO_UDP_PORT       # SimTwo listens for Commands
    bridge: int = BRIDGE_UDP_PORT    # SensorFrames go here
    camera: int = CAMERA_ZMQ_PORT    # ZMQ PUB of the camera frames

    @classmethod
    def free(cls) -> "Ports":
        """Free ports for a run beside others."""
        udp = lambda: free_port(socket.SOCK_DGRAM)  # noqa: E731
        return cls(udp(), udp(), free_port())


def _die_with_parent() -> None:
    """In the child, before exec: get SIGTERM when the process that started it dies (no orphans)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


@dataclass
class SimTwoRun:
    build: Build
    ports: Ports = field(default_factory=Ports)
    scene: str = DEFAULT_SCENE
    camera: bool = True
    bridge_host: str = LOCALHOST
    script: Path | None = None                  # default: simtwo/control.pas
    extra_ini: dict = field(default_factory=dict)
    parts: list | None = None                   # scene.PartPlacement per Part1..4; None: the scene file's
    robot_camera: object | None = None          # a robot file's CameraSpec for AGV.xml (scene.install_camera)
    ready_line: str = READY_LINE                # SimTwo's output that means the script runs (with no SensorFrame)
    workdir: Path | None = None                 # default: a new temporary folder, removed by stop()
    keep: bool = False                          # keep the folder (scene copy, logs) after stop()
    progress: Callable[[str], None] = lambda _m: None

    display: str | None = None
    ready_s: float | None = None                # from SimTwo's start to the script's ready line
    camera_s: float | None = None               # from pressing Ctrl+A to the first whole camera frame
    _xvfb: subprocess.Popen | None = None
    _simtwo: subprocess.Popen | None = None
    _own_dir: bool = False

    # ---- paths -----------------------------------------------------------------------------------------
    @property
    def scene_dir(self) -> Path:
        return self.workdir / "scene"

    @property
    def log_path(self) -> Path:
        return self.workdir / "simtwo.log"

    def log_text(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def messages(self) -> list[str]:
        """SimTwo's editor messages and the script's WriteLn lines so far (patch 11)."""
        return [line for line in self.log_text().splitlines() if line.startswith(("SimTwo: ", "script: "))]

    def scene_ini(self) -> dict:
        """The ini lines this run writes into the scene copy: SimTwo's Hot CPU with the camera open
        (:data:`~.scene.HOT_CPU`), then ``extra_ini`` (which may override it)."""
        out = {"config_Params.ini": dict(HOT_CPU)} if self.camera else {}
        for name, values in self.extra_ini.items():
            out.setdefault(name, {}).update(values)
        return out

    # ---- start -----------------------------------------------------------------------------------------
    def start(self, timeout: float = 90.0) -> "SimTwoRun":
        if self.workdir is None:
            self.workdir = Path(tempfile.mkdtemp(prefix="raf-simtwo-"))
            self._own_dir = True
        self.workdir = Path(self.workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        try:
            settings = SceneSettings(udp_port=self.ports.udp, bridge_host=self.bridge_host,
                                     bridge_port=self.ports.bridge, extra_ini=self.scene_ini(), parts=self.parts,
                                     camera=self.robot_camera)
            if self.script is not None:
                settings.script = Path(self.script)
            install(self.build.simtwo_dir, self.scene_dir, settings, self.scene)
            self._start_xvfb()
            self._start_simtwo()
            self._wait_ready(timeout)
            if self.camera:
                self.open_camera()
        except BaseException:
            self.stop()
            raise
        return self

    def _start_xvfb(self) -> None:
        r, w = os.pipe()
        try:
            with open(self.workdir / "xvfb.log", "wb") as log:
                self._xvfb = subprocess.Popen(
                    ["Xvfb", "-displayfd", str(w), "-screen", "0", SCREEN, "-dpi", "96", "-nolisten", "tcp",
                     "-noreset"], pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
                    preexec_fn=_die_with_parent)
        except FileNotFoundError:
            os.close(r)
            raise SimTwoError("Xvfb is not installed (apt-get install xvfb)") from None
        finally:
            os.close(w)
        with os.fdopen(r) as f:
            number = f.readline().strip()  # Xvfb writes its display number when it is ready
        if not number:
            raise SimTwoError(f"Xvfb did not start: {(self.workdir / 'xvfb.log').read_text(errors='replace')}")
        self.display = f":{number}"

    def _env(self) -> dict:
        env = dict(os.environ)
        env.update(DISPLAY=self.display, LIBGL_ALWAYS_SOFTWARE="1", SIMTWO_CAMERA_PORT=str(self.ports.camera))
        return env

    def _start_simtwo(self) -> None:
        self.progress(f"SimTwo: {self.scene} on display {self.display}, udp {self.ports.udp}, frames to "
                      f"{self.bridge_host}:{self.ports.bridge}, camera tcp {self.ports.camera}")
        self._t_start = time.monotonic()
        with open(self.log_path, "wb") as log:
            self._simtwo = subprocess.Popen([str(self.build.executable), str(self.scene_dir)],
                                            cwd=self.build.simtwo_dir, env=self._env(), stdout=log,
                                            stderr=subprocess.STDOUT, start_new_session=True,
                                            preexec_fn=_die_with_parent)

    def _wait_ready(self, timeout: float) -> None:
        """Until the script reports that it streams. It does not read the bridge's port: a bridge started at
        the same time (roslaunch) must be able to bind it."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.check()
            messages = self.messages()
            if any(ERROR_RE.match(m) for m in messages):
                raise SimTwoError("SimTwo reports script errors:\n" + "\n".join(messages[-20:]))
            if any(m.startswith(self.ready_line) for m in messages):
                break
            time.sleep(0.05)
        else:
            raise SimTwoError(f"SimTwo's script did not print {self.ready_line[len('script: '):]!r} within "
                              f"{timeout:.0f} s; its messages:\n" + self.tail())
        self.ready_s = time.monotonic() - self._t_start
        self.progress(f"SimTwo: streaming {self.ready_s:.1f} s after the start")

    def _xdotool(self, *args: str) -> str:
        r = subprocess.run(["xdotool", *args], env=self._env(), capture_output=True, text=True, timeout=20)
        return r.stdout.strip()

    def open_camera(self, timeout: float = 30.0) -> None:
        """Open SimTwo's Cameras window (Ctrl+A in the viewer) and wait for a whole frame on the camera port."""
        import zmq

        if shutil.which("xdotool") is None:
            raise SimTwoError("xdotool is not installed (apt-get install xdotool): it opens SimTwo's camera")
        ctx = zmq.Context.instance()
        sub = ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://127.0.0.1:{self.ports.camera}")
        t0 = time.monotonic()
        pressed = 0.0
        try:
            while time.monotonic() - t0 < timeout:
                self.check()
                if time.monotonic() - pressed > 8.0 and not self._xdotool("search", "--name", "^Cameras$"):
                    viewer = self._xdotool("search", "--name", "^SimTwo - v").split()
                    if viewer:
                        self._xdotool("windowfocus", "--sync", viewer[-1])
                        self._xdotool("key", "--clearmodifiers", "ctrl+a")
                        pressed = time.monotonic()
                if sub.poll(200):
                    frame = sub.recv()
                    if len(frame) != CAMERA_FRAME_BYTES:
                        raise SimTwoError(f"SimTwo's camera frames have {len(frame)} bytes, not 640 x 480 x 4 = "
                                          f"{CAMERA_FRAME_BYTES} (the display's dpi rescaled the Cameras window?)")
                    self.camera_s = time.monotonic() - t0
                    self.progress(f"SimTwo: camera frames on tcp {self.ports.camera} "
                                  f"({self.camera_s:.1f} s after opening its window)")
                    return
            raise SimTwoError(f"no camera frame within {timeout:.0f} s of opening SimTwo's Cameras window")
        finally:
            sub.close()

    # ---- while running ---------------------------------------------------------------------------------
    def check(self) -> None:
        """SimTwoError when SimTwo or its X server has exited."""
        for name, p in (("SimTwo", self._simtwo), ("Xvfb", self._xvfb)):
            if p is not None and p.poll() is not None:
                raise SimTwoError(f"{name} exited with code {p.returncode}; SimTwo's messages:\n{self.tail()}")

    @property
    def alive(self) -> bool:
        return self._simtwo is not None and self._simtwo.poll() is None

    @property
    def pid(self) -> int | None:
        return self._simtwo.pid if self._simtwo else None

    def tail(self, n: int = 25) -> str:
        return "\n".join(self.log_text().splitlines()[-n:]) or "(nothing)"

    # ---- stop ------------------------------------------------------------------------------------------
    def stop(self) -> None:
        """End SimTwo and its X server (idempotent) and remove the run's folder unless ``keep``."""
        for p in (self._simtwo, self._xvfb):
            if p is not None:
                stop_process(p, signal.SIGTERM, timeout=5.0)
        self._simtwo = self._xvfb = None
        if self._own_dir and not self.keep and self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> "SimTwoRun":
        return self.start() if self._simtwo is None else self

    def __exit__(self, *exc) -> None:
        self.stop()
