"""A small fake SimTwo for bridge tests: SensorFrames over UDP, camera frames over ZMQ, no physics.

It integrates the commanded V, W kinematically (so a cmd_vel visibly moves it), counts encoder ticks the
way SimTwo does (floor of the accumulated wheel angle, remainder carried), measures a synthetic LIDAR in
turn like ranger2d (every ray reads 1.0 m + 0.001 m * ray index, ray 7 never returns) and, like SimTwo,
delivers it a whole sweep at once every sweep period, 1 ms after a cycle's end (zeros before the first;
``lidar_update="per_ray"``: each ray as soon as measured, the old idealisation), and renders a
synthetic camera frame on SimTwo's render clock (60 FPS, every 4th tick), published BEFORE the SensorFrame
of the cycle it falls in. Each camera frame carries its true render time for tests: pixel row 0 (the top
row, after the bottom-up flip) holds the tick number k (render time k/60 s) in its first 4 bytes,
little-endian, B channel first.

Use in-process (``FakeSim(...).start()`` runs a thread) or as a script:
``python tests/fakesim.py --lockstep --camera ENDPOINT [--bridge HOST:PORT]``; ``--help`` shows the default
bridge address and an endpoint (robotatfactory.simtwo.ports' names).
Also answers nothing: it only records the Command datagrams the bridge sends back.
"""
from __future__ import annotations

import argparse
import math
import socket
import threading
import time
from dataclasses import dataclass

import numpy as np

from robotatfactory.robot import load_robot
from robotatfactory.simtwo import Command, ProtocolError, SensorFrame, encode_frame
from robotatfactory.simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST


@dataclass
class Received:
    seq: int
    v: float
    w: float
    magnet: bool
    t_wall: float


def tick_of_image(bgr: np.ndarray) -> int:
    """The render tick a fake frame was made at (see the module docstring)."""
    return int.from_bytes(bytes(bgr[0, :2, :].reshape(-1)[:4]), "little")


class FakeSim:
    def __init__(self, bridge=(LOCALHOST, BRIDGE_UDP_PORT), camera: str | None = None, lockstep=False, realtime=True,
                 rate=1.0, lockstep_timeout=0.5, rays=360, start_seq=0, bind_host=LOCALHOST, width=640,
                 height=480, lidar_update="sweep"):
        self.robot = load_robot()
        self.lidar_update = lidar_update  # "sweep" (SimTwo) | "per_ray"
        self.bridge = bridge
        self.lockstep, self.realtime, self.rate = lockstep, realtime, rate
        self.lockstep_timeout = lockstep_timeout
        self.rays = rays
        self.width, self.height = width, height
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((bind_host, 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.camera_endpoint = camera
        self.pub = None
        if camera:
            import zmq

            self.zctx = zmq.Context.instance()
            self.pub = self.zctx.socket(zmq.PUB)
            self.pub.setsockopt(zmq.SNDHWM, 2)
            self.pub.setsockopt(zmq.LINGER, 0)
            if camera.endswith(":0") or camera.endswith(":*"):
                self.pub.bind(camera.rsplit(":", 1)[0] + ":*")
                self.camera_endpoint = self.pub.getsockopt(zmq.LAST_ENDPOINT).decode()
            else:
                self.pub.bind(camera)
        self.received: list[Received] = []
        self.loss = 0.0  # probability of not sending a SensorFrame (a lost datagram)
        self.lost = 0
        self._rng = np.random.default_rng(0)
        self.sent = 0
        self.frames_published = 0
        self.timeouts = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._paused = threading.Event()
        self._thread = None
        self.reset(start_seq)

    # -- state -----------------------------------------------------------------------------------------------
    def reset(self, start_seq: int = 0) -> None:
        """A scene restart: Seq from ``start_seq`` (0 normally), time and totals from 0."""
        with getattr(self, "_lock", threading.Lock()):
            self.seq = start_seq
            self.step = 0  # physics steps (1 ms) since t = 0
            self.x, self.y, self.theta = -0.6, -0.4, 0.0
            self.v = self.w = 0.0
            self.magnet = False
            self.wheel_angle = [0.0, 0.0]
            self.enc_frac = [0.0, 0.0]
            self.total = [0, 0]
            self.measured = np.full(self.rays, -1.0)  # the rays as last measured
            # what a frame carries: SimTwo's Measures[] (0 until the first sweep is delivered)
            self.ranges = np.zeros(self.rays) if self.lidar_update == "sweep" else self.measured
            self.next_render_tick = 0

    def _teleport(self, data: bytes) -> None:
        """The teleport labels of a Command, as simtwo/control.pas applies them (each TpId once; the robot's
        own only: the fake has no parts, those are recorded in ``teleports``)."""
        from robotatfactory.simtwo.teleport import Teleport

        try:
            tp = Teleport.from_datagram(data)
        except ProtocolError:
            return
        if tp is None or tp.id == getattr(self, "last_teleport_id", 0):
            return
        self.last_teleport_id = tp.id
        self.teleports = getattr(self, "teleports", []) + [tp]
        if not tp.target:
            self.x, self.y, self.theta = tp.x, tp.y, tp.theta

    def pose(self):
        with self._lock:
            return self.x, self.y, self.theta

    # -- one control cycle -----------------------------------------------------------------------------------
    def cycle(self) -> SensorFrame:
        """Advance 40 ms, publish the camera frames rendered in it, then send the SensorFrame."""
        r, b = self.robot.wheel_radius, self.robot.track
        n = self.rays
        period_ns, dt_ns = int(self.robot.lidar.period * 1e9), 1_000_000
        with self._lock:
            wl, wr = (self.v - self.w * b / 2) / r, (self.v + self.w * b / 2) / r
            renders = []
            for _ in range(40):
                prev = (self.step * n * dt_ns) // period_ns
                self.step += 1
                t = self.step / 1000
                # the wheel speeds from V, W over the wheels' spacing (control.pas), the turn about the track the
                # robot really turns with (robot_simtwo.json odometry_track: SimTwo's robot turns 2.1 % more)
                ds, dth = self.v * 0.001, r * (wr - wl) / self.robot.odometry_track * 0.001
                self.x += ds * math.cos(self.theta + dth / 2)
                self.y += ds * math.sin(self.theta + dth / 2)
                self.theta = math.remainder(self.theta + dth, 2 * math.pi)
                self.wheel_angle[0] += wl * 0.001
                self.wheel_angle[1] += wr * 0.001
                c = (self.step * n * dt_ns) // period_ns
                for g in range(prev, c):
                    i = g % n
                    self.measured[i] = -1.0 if i == 7 else 1.0 + 0.001 * i
                if self.lidar_update == "sweep" and self.step > 1 and ((self.step - 1) * dt_ns) % period_ns == 0:
                    # delivered at once, 1 ms after a cycle's end, as SimTwo's UpdateMeasures falls
                    self.ranges = self.measured.copy()
                while self.next_render_tick / 60 <= t + 1e-12:
                    renders.append(self.next_render_tick)
                    self.next_render_tick += 4
            deltas = []
            for k in (0, 1):
                acc = self.enc_frac[k] + self.wheel_angle[k] * self.robot.ticks_per_rev / (2 * math.pi)
                self.wheel_angle[k] = 0.0
                d = math.floor(acc)
                self.enc_frac[k] = acc - d
                self.total[k] += d
                deltas.append(d)
            frame = SensorFrame(seq=self.seq, time_ms=self.step, enc_delta=tuple(deltas), enc_total=tuple(self.total),
                                x=self.x, y=self.y, theta=self.theta, contact=False, magnet=self.magnet,
                                ranges=self.ranges.copy())
            self.seq += 1
        for k in renders:
            self.publish_camera(k)
        if self.loss and self._rng.random() < self.loss:
            self.lost += 1
            frame.lost = True
        else:
            self.send(frame.encode())
        return frame

    def publish_camera(self, tick: int, nbytes: int | None = None) -> None:
        if self.pub is None:
            return
        if nbytes is not None:
            self.pub.send(b"\0" * nbytes)
            return
        img = np.zeros((self.height, self.width, 3), np.uint8)
        img[:, :, 1] = 80
        img[self.height // 3: 2 * self.height // 3, self.width // 3: 2 * self.width // 3] = (200, 50, 20)
        img[0, :2, :] = np.frombuffer(int(tick).to_bytes(6, "little"), np.uint8).reshape(2, 3)
        self.pub.send(encode_frame(img, bottom_up=True), copy=False)
        self.frames_published += 1

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.bridge)
        self.sent += 1

    def drain(self, wait_for_seq: int | None = None, timeout: float = 0.0) -> bool:
        """Read Commands; True when one answering ``wait_for_seq`` arrived (within ``timeout``)."""
        end = time.monotonic() + timeout
        got = False
        while True:
            try:
                data, _ = self.sock.recvfrom(65536)
            except socket.timeout:
                if time.monotonic() >= end or got:
                    return got
                continue
            try:
                cmd = Command.decode(data)
            except ProtocolError:
                continue
            with self._lock:
                self._teleport(data)
                self.received.append(Received(cmd.seq, cmd.v, cmd.w, cmd.magnet, time.monotonic()))
                if cmd.seq == wait_for_seq or wait_for_seq is None:
                    self.v, self.w, self.magnet = cmd.v, cmd.w, cmd.magnet
                    got = True
            if got and wait_for_seq is not None:
                return True

    # -- running ---------------------------------------------------------------------------------------------
    def run(self, cycles: int | None = None) -> None:
        t0 = time.monotonic()
        i = 0
        while not self._stop.is_set() and (cycles is None or i < cycles):
            if self._paused.is_set():
                time.sleep(0.01)
                t0 = time.monotonic() - i * 0.04 / self.rate
                continue
            f = self.cycle()
            i += 1
            if self.lockstep and not getattr(f, "lost", False):
                if not self.drain(f.seq, self.lockstep_timeout):
                    self.timeouts += 1
                    with self._lock:
                        self.v = self.w = 0.0
            else:
                self.drain(None, 0.0)
            if self.realtime:
                wait = t0 + i * 0.04 / self.rate - time.monotonic()
                if wait > 0:
                    end = time.monotonic() + wait
                    while time.monotonic() < end:
                        self.drain(None, 0.0)
                        time.sleep(min(0.005, max(0.0, end - time.monotonic())))

    def start(self) -> "FakeSim":
        self._thread = threading.Thread(target=self.run, daemon=True)
        self._thread.start()
        return self

    def pause(self) -> None:
        self._paused.set()

    def resume(self) -> None:
        self._paused.clear()

    def stop(self) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(2.0)
        self.sock.close()
        if self.pub is not None:
            self.pub.close(0)

    def commands_for(self, seq: int) -> list[Received]:
        with self._lock:
            return [r for r in self.received if r.seq == seq]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bridge", default=f"{LOCALHOST}:{BRIDGE_UDP_PORT}", help="HOST:PORT (default: %(default)s)")
    ap.add_argument("--camera", default=None, help=f"ZMQ endpoint to bind, e.g. tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}")
    ap.add_argument("--lockstep", action="store_true")
    ap.add_argument("--fast", action="store_true")
    ap.add_argument("--rate", type=float, default=1.0, help="real-time factor when not --fast")
    ap.add_argument("--cycles", type=int, default=None)
    a = ap.parse_args()
    host, port = a.bridge.rsplit(":", 1)
    sim = FakeSim((host, int(port)), a.camera, lockstep=a.lockstep, realtime=not a.fast, rate=a.rate)
    try:
        sim.run(a.cycles)
    except KeyboardInterrupt:
        pass
    finally:
        sim.stop()


if __name__ == "__main__":
    main()
