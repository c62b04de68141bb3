"""The bridge's camera half: ZMQ frames to ``camera/image_raw`` + ``camera/camera_info``, in its own process.

Why a separate process: converting and serialising a 1.2 MB frame in the middleware holds Python's GIL for around a
millisecond at a time; in the bridge's process that delay lands on the control path (the Command reply and
odom). The bridge node starts this node (``<bridge name>_camera``, same namespace) with
``python -m robotatfactory.ros.camera_node`` and feeds it, over a local SOCK_SEQPACKET socket pair, the
``Tms`` and kernel arrival time of every accepted SensorFrame (and a reset mark on a simulator restart): the
camera stamping (``simtwo.timing.CameraStamper``) needs both streams' arrival times on one clock
(``time.monotonic()`` is system-wide). The bridge's writes are non-blocking: if this process stalls, timing
messages are dropped, never the control path. This process exits when the bridge does (the socket closes).

Threads: ZMQ receive (keeps only the newest frame, counts the skipped ones and hands the count on: the grid
rule counts render ticks), publish (size check, stamp -- which first applies any timing message still
waiting in the socket; by default (``~camera/bracket: elapsed``) the stamp follows from the SensorFrames
already received, the ``nearest`` rule may wait up to ``~camera/max_wait`` for the one after the frame --,
flip, bgr8), timing reader, diagnostics (its own ``<node>: camera`` status on ``/diagnostics``).
"""
from __future__ import annotations

import argparse
import json
import os
import socket
import struct
import sys
import threading
import time

TIMING = struct.Struct("<qdq")  # Tms (or -1: reset), arrival (monotonic seconds), CamN (-1: not sent)
RESET = -1
RCVHWM = 64  # camera frames queued in ZMQ before it drops any (77 MB at 640x480 BGRA)
SUPERSEDED = object()  # CameraBridge._stamp: a newer frame arrived while this one waited


def camera_stamper(cfg):
    """The camera stamping (:class:`~robotatfactory.simtwo.timing.CameraStamper`) the bridge's settings ask for."""
    from ..simtwo.timing import CameraStamper

    cam = cfg.camera
    return CameraStamper(cfg.control_period_ms, cam.render_fps, cam.decimation, max_wait=cam.max_wait,
                         use_grid=cam.use_grid, rule=cam.bracket, latency=cam.latency)


class CameraBridge:
    def __init__(self, cfg, node, timing_sock: socket.socket | None = None):
        from ..ratelog import LogLimiter
        from ..simtwo.stream import RateMeter

        self.cfg = cfg
        self.node = node  # the middleware's node (.mw)
        self.stamper = camera_stamper(cfg)
        self.timing_sock = timing_sock
        if timing_sock is not None:
            # non-blocking (not merely MSG_DONTWAIT: a socket in timeout mode, as rospy's default timeout
            # makes new sockets, would wait for data anyway); the timing thread waits in select()
            timing_sock.setblocking(False)
        self.rate = RateMeter()
        self.log = LogLimiter(cfg.settings.log_period)
        self.counts = {"received": 0, "skipped": 0, "wrong_size": 0, "published": 0, "timing_messages": 0,
                       "publisher_restarts": 0}
        self._mail = None
        self._wait_deadline: float | None = None  # the first waiting frame's bound (monotonic s), see _stamp
        self._cv = threading.Condition()
        self._timing_cv = threading.Condition()  # notified on every SensorFrame timing message
        self._drain_lock = threading.Lock()  # one reader of the timing socket at a time, in order
        self._running = False
        self.paced = None  # camera_paced.PacedCamera when ~pace/enabled
        self._info = None  # the camera_info published with each image (its stamp set each time)
        self._threads: list[threading.Thread] = []
        self.parent_gone = threading.Event()

    def start(self) -> "CameraBridge":
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import CameraInfo, Image

        from .mw import QoS

        t, node = self.cfg.topics, self.node
        q = QoS.RELIABLE if self.cfg.pace.enabled else QoS.SENSOR  # paced: every frame counts (pace.py)
        self.pub_image = node.publisher(t["image"], Image, q, 2)
        self.pub_info = node.publisher(t["camera_info"], CameraInfo, q, 2)
        self.pub_diag = node.publisher(t["diagnostics"], DiagnosticArray, QoS.RELIABLE, 10)
        self._running = True
        loops = (self._rx, self._publish)
        if self.cfg.pace.enabled:  # every frame, stamped with the simulation time it carries (camera_paced.py)
            from .camera_paced import PacedCamera

            self.paced = PacedCamera(self)
            loops = (self.paced.rx, self.paced.publish)
        for fn in loops + (self._diag_loop,) + ((self._timing,) if self.timing_sock else ()):
            th = threading.Thread(target=self._guard, args=(fn,), daemon=True, name=f"raf-camera-{fn.__name__}")
            th.start()
            self._threads.append(th)
        return self

    def stop(self) -> None:
        self._running = False
        with self._cv:
            self._cv.notify_all()
        for th in self._threads:
            th.join(2.0)

    def _guard(self, fn):
        while self._running and self.node.ok():
            try:
                fn()
                return
            except Exception as e:  # noqa: BLE001 - never die on bad input
                if self._running:
                    self.node.error(f"camera: {fn.__name__} failed: {e!r}; restarting it")
                    time.sleep(0.2)

    def _warn(self, key, text):
        suffix = self.log(key)
        if suffix is not None:
            self.node.warn(text + suffix)

    # -- the SensorFrame timing from the bridge --------------------------------------------------------------
    def _timing(self) -> None:
        import select

        while self._running and not self.parent_gone.is_set():
            if select.select([self.timing_sock], [], [], 0.5)[0]:
                self._drain_timing()

    def _drain_timing(self) -> None:
        """Apply every timing message waiting in the socket. Called by the timing thread and, before each
        stamp, by the publishing thread: on a loaded machine the timing thread may not have run since the
        SensorFrames that bracket a frame arrived, and a stamp must not be decided without them."""
        s = self.timing_sock
        if s is None:
            return
        with self._drain_lock:
            while True:
                try:
                    data = s.recv(64)
                except BlockingIOError:
                    return
                except OSError:
                    data = b""
                if not data:  # the bridge went away
                    self.parent_gone.set()
                    return
                tms, arrival, camera_frames = TIMING.unpack(data[:TIMING.size])
                self.counts["timing_messages"] += 1
                if self.paced is not None and tms != RESET:
                    self.paced.on_timing(tms, camera_frames)
                elif tms == RESET:
                    self.stamper.reset()
                else:
                    self.stamper.on_sensor_frame(tms, arrival)
                with self._timing_cv:
                    self._timing_cv.notify_all()

    # -- frames ------------------------------------------------------------------------------------------------
    def _rx(self) -> None:
        import zmq

        ctx = zmq.Context.instance()
        sock = ctx.socket(zmq.SUB)
        # a long queue: frames are counted, not lost unseen, while this process is held up (the stamper counts
        # render ticks from frame to frame); the loop below still publishes only the newest
        sock.setsockopt(zmq.RCVHWM, RCVHWM)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.SUBSCRIBE, b"")
        # connection events tell a restarted publisher (ZMQ reconnects by itself; frames carry no sequence)
        monitor = sock.get_monitor_socket(zmq.EVENT_CONNECTED)
        poller = zmq.Poller()
        poller.register(sock, zmq.POLLIN)
        poller.register(monitor, zmq.POLLIN)
        connected = False
        sock.connect(self.cfg.camera.endpoint)
        try:
            while self._running:
                ready = dict(poller.poll(200))
                if monitor in ready:
                    connected = self._on_connect_events(monitor, connected)
                if sock not in ready:
                    continue
                msg = sock.recv(copy=False)
                arrival = time.monotonic()
                self.counts["received"] += 1
                drained = 0
                while sock.poll(0):  # keep only the newest frame
                    msg = sock.recv(copy=False)
                    arrival = time.monotonic()
                    self.counts["received"] += 1
                    drained += 1
                with self._cv:
                    skipped = drained  # frames dropped unpublished since the last one handed on (for stamping)
                    if self._mail is not None:  # the publisher has not taken the previous one: skipped too
                        skipped += 1 + self._mail[2]
                        drained += 1
                    self.counts["skipped"] += drained
                    self._mail = (arrival, msg, skipped)
                    self._cv.notify()
                with self._timing_cv:  # a stamp waiting for its SensorFrame can decide now
                    self._timing_cv.notify_all()
        finally:
            sock.disable_monitor()
            monitor.close(0)
            sock.close(0)

    def _on_connect_events(self, monitor, connected: bool) -> bool:
        """Count a reconnection to the camera endpoint as a publisher restart and re-synchronise the stamper's
        frame counting (the SensorFrames it knows stay valid). Returns whether a connection was ever made."""
        import zmq
        from zmq.utils.monitor import recv_monitor_message

        while monitor.poll(0):
            event = recv_monitor_message(monitor)
            if event["event"] != zmq.EVENT_CONNECTED:
                continue
            if connected:
                self.counts["publisher_restarts"] += 1
                self.stamper.resync_frames()
                self._warn("restart", f"camera: the publisher at {self.cfg.camera.endpoint} restarted "
                                      f"(reconnected); frame stamping re-synchronised")
            connected = True
        return connected

    def _publish(self) -> None:
        carried = 0  # skipped frames counted with a wrong-sized message, passed on to the next frame
        while self._running:
            with self._cv:
                while self._mail is None and self._running:
                    self._cv.wait(0.2)
                if self._mail is None:
                    continue
                arrival, msg, skipped = self._mail
                self._mail = None
            skipped += carried
            carried = 0
            if not self._size_ok(msg.buffer):
                carried = skipped  # not a frame of this camera: the frames skipped before it still count
                continue
            est = self._stamp(arrival, skipped)
            if est is SUPERSEDED:  # a newer frame waits for its SensorFrames instead: this one is skipped
                with self._cv:
                    self.counts["skipped"] += 1
                carried = skipped + 1
                continue
            if est is None:
                self._warn("clock", "camera: frame before any SensorFrame: no simulation time to stamp it with, "
                                    "dropped")
                continue
            self.publish_frame(msg.buffer, est.stamp, arrival)

    def _size_ok(self, buf) -> bool:
        cam = self.cfg.robot.camera
        expected = cam.width * cam.height * 4
        if memoryview(buf).nbytes == expected:
            return True
        self.counts["wrong_size"] += 1
        self._warn("size", f"camera: ignoring a frame of {memoryview(buf).nbytes} bytes (expected {cam.width}x"
                           f"{cam.height}x4 = {expected}; ~camera/width, ~camera/height)")
        return False

    def publish_frame(self, buf, stamp_s: float, arrival: float | None = None) -> bool:
        """Publish one SimTwo frame (B G R A, bottom row first unless the camera says otherwise) as bgr8 with
        its camera_info, stamped ``stamp_s``; False (counted, warned) if it is not this camera's size."""
        import numpy as np

        from . import messages as rm

        if not self._size_ok(buf):
            return False
        cam = self.cfg.robot.camera
        w, h = cam.width, cam.height
        if self._info is None:
            self._info = rm.camera_info(rm.zero_stamp(), self.cfg.frames["camera_optical"], w, h, cam.fx, cam.fy,
                                        cam.cx, cam.cy, cam.distortion)
        # B G R A (bottom row first) to top-row-first bgr8 bytes in ONE strided copy
        bgra = np.frombuffer(buf, dtype=np.uint8).reshape(h, w, 4)
        data = (bgra[::-1, :, :3] if cam.bottom_up else bgra[:, :, :3]).tobytes()
        stamp = rm.stamp_s(stamp_s)
        self.pub_image.publish(rm.image_bgr8(stamp, self.cfg.frames["camera_optical"], data, w, h))
        self._info.header.stamp = stamp
        self.pub_info.publish(self._info)
        self.counts["published"] += 1
        self.rate.tick(time.monotonic() if arrival is None else arrival)
        return True

    def _stamp(self, arrival: float, skipped: int):
        """The frame's stamp; waits (briefly) for the SensorFrame after it when the stamper needs it.
        :data:`SUPERSEDED` when a newer frame arrived while it waited: that one is published instead.

        The wait's bound is the first waiting frame's deadline, kept across the frames that supersede it. A
        newer frame is no reason to decide early: the simulator sent this frame's SensorFrames before it, but a
        loaded bridge may pass them on later still, and a stamp decided without them is early by a cycle or
        more (CI, ROS 2: frames 81 and 148 ms early). Nor is it a reason to wait anew: frames keep coming
        where SensorFrames do not."""
        from ..simtwo.timing import Pending

        while True:
            self._drain_timing()
            with self._timing_cv:
                est = self.stamper.stamp(arrival, skipped=skipped)
                if not isinstance(est, Pending):
                    self._wait_deadline = None
                    return est
                if self._wait_deadline is None:
                    self._wait_deadline = est.deadline
                if time.monotonic() >= self._wait_deadline:  # waited long enough: decide with what is known
                    self._wait_deadline = None
                    return self.stamper.stamp(arrival, now=est.deadline, skipped=skipped)
                if self._mail is not None:
                    return SUPERSEDED
                self._timing_cv.wait(max(0.0, min(est.deadline, self._wait_deadline) - time.monotonic()) + 1e-4)

    # -- diagnostics -------------------------------------------------------------------------------------------
    def _diag_loop(self) -> None:
        from .cli import publish_every

        publish_every(self.cfg.diagnostics.period, lambda: self._running, self.pub_diag, self.diagnostics,
                      errors=(Exception,))

    def diagnostics(self, now: float | None = None):
        from diagnostic_msgs.msg import DiagnosticArray

        from . import messages as rm
        from .mw.base import ERROR, OK, WARN

        now = time.monotonic() if now is None else now
        cfg, c = self.cfg, self.counts
        age = self.rate.age(now)
        if age is None:
            level, text = WARN, f"no camera frame yet from {cfg.camera.endpoint}"
        elif age > cfg.diagnostics.stale_error:
            level, text = ERROR, f"stale: no camera frame for {age:.1f} s"
        elif age > 4 * cfg.diagnostics.stale_warn:
            level, text = WARN, f"no camera frame for {age:.1f} s"
        else:
            level, text = OK, "receiving"
        phase = self.stamper.locked_phase
        vals = {"frame_rate_hz": self.rate.rate(now), "staleness_s": -1.0 if age is None else age,
                "received": c["received"], "published": c["published"], "skipped": c["skipped"],
                "rejected_wrong_size": c["wrong_size"], "publisher_restarts": c["publisher_restarts"],
                "locked_render_phase": -1 if phase is None else phase,
                "timing_messages": c["timing_messages"]}
        vals.update({f"stamps_{k}": v for k, v in self.stamper.counters.as_dict().items()})
        arr = DiagnosticArray()
        arr.header.stamp = rm.zero_stamp()
        arr.status = [rm.diagnostic_status(f"{self.node.name}: camera", level, text, cfg.camera.endpoint, vals)]
        return arr


class CameraLink:
    """The bridge's side: starts the camera process and sends it the SensorFrame timing (non-blocking).

    ``node`` (``camera.process: bridge``): run the camera half in this process instead, on ``node`` (the
    bridge's :meth:`~.mw.base.Node.sibling`), fed through the same socket pair."""

    def __init__(self, params: dict, name: str, namespace: str, node=None):
        import subprocess

        self.parent_sock, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.parent_sock.setblocking(False)
        self.dropped = 0
        self.proc = self.cam = None
        if node is not None:
            from .config import load_config

            self.cam = CameraBridge(load_config(params), node, child).start()
            return
        args = [sys.executable, "-m", "robotatfactory.ros.camera_node", "--fd", str(child.fileno()),
                "--params", json.dumps(params), "--name", name, "--ns", namespace or "/"]
        self.proc = subprocess.Popen(args, pass_fds=[child.fileno()])
        child.close()

    def frame(self, time_ms: int, arrival: float, camera_frames: int | None = None) -> None:
        self._send(TIMING.pack(int(time_ms), float(arrival), -1 if camera_frames is None else int(camera_frames)))

    def reset(self) -> None:
        self._send(TIMING.pack(RESET, 0.0, -1))

    def _send(self, data: bytes) -> None:
        try:
            self.parent_sock.send(data)
        except (BlockingIOError, OSError):
            self.dropped += 1

    def close(self, timeout: float = 5.0) -> None:
        import subprocess

        self.parent_sock.close()  # the camera process sees EOF and exits
        if self.cam is not None:
            self.cam.stop()
            self.cam.timing_sock.close()
            return
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.terminate()
            try:
                self.proc.wait(2)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def main(argv: list[str] | None = None) -> int:
    from ..errors import ConfigError
    from .config import load_config
    from .mw import api

    mw = api()
    argv = list(sys.argv if argv is None else argv)
    ap = argparse.ArgumentParser(prog="camera_node", description=__doc__.splitlines()[0])
    ap.add_argument("--fd", type=int, help="SOCK_SEQPACKET socket with the bridge's SensorFrame timing")
    ap.add_argument("--params", default="{}", help="the bridge's parameters as JSON")
    ap.add_argument("--name", default="raf_bridge_camera", help="node name")
    ap.add_argument("--ns", default="/", help="node namespace")
    args = ap.parse_args(mw.myargv(argv)[1:])
    node = mw.init_node(args.name, argv=[argv[0]], signals=False, namespace=args.ns)
    sys.setswitchinterval(0.0005)
    try:
        cfg = load_config(json.loads(args.params))
    except ConfigError as e:
        node.fatal(f"camera: {e}")
        return 2
    sock = socket.socket(fileno=args.fd) if args.fd is not None else None
    cam = CameraBridge(cfg, node, sock).start()
    ppid = os.getppid()
    try:
        while node.ok() and not cam.parent_gone.is_set():
            if sock is not None and os.getppid() != ppid:
                break
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    cam.stop()
    node.shutdown("bridge gone")
    return 0


if __name__ == "__main__":
    sys.exit(main())
