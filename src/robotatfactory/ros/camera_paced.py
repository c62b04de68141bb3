"""The camera process paced by simulation time (``~pace/enabled``, with ``raf sim --paced``): every frame is
published, none skipped, stamped with the simulation time it carries (the two-part ZMQ message of a paced raf
sim), and each SensorFrame's cycle is paced once the frames it counts (its ``CamN`` label, passed on by the
bridge) are out. Nothing here reads a wall clock but the safety net's timeout (``~pace/timeout``)."""
from __future__ import annotations

import threading
import time
from collections import deque


class PacedCamera:
    """The paced receive and publish loops of :class:`~.camera_node.CameraBridge` (``cam``)."""

    def __init__(self, cam):
        from .pace import Pacer

        self.cam = cam
        self.pacer = Pacer(cam.node, "camera", None, timeout=cam.cfg.pace.timeout)
        self.frames: deque = deque()  # (stamp s, index, payload) in arrival order
        self.cycles: deque = deque()  # (Tms, CamN) of the SensorFrames, in order
        self.received = 0  # camera frames received since the start
        self.taken = 0  # ... and handed to publishing
        self.cv = threading.Condition()

    def on_timing(self, tms: int, camera_frames: int) -> None:
        """A SensorFrame's timing message (from the bridge): pace its cycle once ``camera_frames`` are out."""
        with self.cv:
            self.cycles.append((tms, camera_frames))
            self.cv.notify_all()

    def rx(self) -> None:
        import zmq

        from ..simtwo.camera import parse_camera_header

        cam = self.cam
        sock = zmq.Context.instance().socket(zmq.SUB)
        sock.setsockopt(zmq.RCVHWM, 0)  # paced: never drop (the loop waits for this process)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.SUBSCRIBE, b"")
        sock.connect(cam.cfg.camera.endpoint)
        try:
            while cam._running:
                if not sock.poll(200):
                    continue
                parts = sock.recv_multipart(copy=False)
                cam.counts["received"] += 1
                head = parse_camera_header(parts[0].bytes) if len(parts) == 2 else None
                if head is None:
                    cam.counts["wrong_size"] += 1
                    cam._warn("paced", "camera: paced, but a frame came without its simulation time (is raf sim "
                                       "--paced? SimTwo cannot be paced): ignored")
                    continue
                with self.cv:
                    self.frames.append((head[0], head[1], parts[1]))
                    self.received += 1
                    self.cv.notify_all()
        finally:
            sock.close(0)

    def publish(self) -> None:
        """Cycle by cycle: wait for the frames the SensorFrame counts, publish them, pace the cycle."""
        cam = self.cam
        while cam._running:
            with self.cv:
                while not self.cycles and cam._running:
                    self.cv.wait(0.2)
                if not self.cycles:
                    continue
                tms, need = self.cycles[0]
                end = time.monotonic() + self.pacer.timeout
                while self.received < need and cam._running and time.monotonic() < end:
                    self.cv.wait(0.05)
                if self.received < need:
                    cam._warn("paced-timeout", f"camera: paced: cycle {tms} ms counts {need} camera frames, "
                                               f"{self.received} came in {self.pacer.timeout:g} s: going on")
                    self.received = max(self.received, need)
                self.cycles.popleft()
                out = []
                while self.frames and self.taken < need:
                    out.append(self.frames.popleft())
                    self.taken += 1
                self.taken = max(self.taken, need)
            for stamp, _index, payload in out:
                if cam.publish_frame(payload, stamp):
                    self.pacer.sent("image")
                    self.pacer.sent("camera_info")
            self.pacer.done(tms / 1000.0)
