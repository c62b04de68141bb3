"""Several robots in one ``raf sim``: one set of endpoints per robot, one physics scene, one clock.

Robot k (1-based) has its own command socket, SensorFrame destination and camera publisher, at ports
derived from robot 1's by ``PORT_STRIDE`` (:func:`robot_ports`): with the defaults robot 1 uses SIMTWO_UDP_PORT
(commands), BRIDGE_UDP_PORT (frames to its bridge) and tcp CAMERA_ZMQ_PORT (camera) of simtwo/ports.py, robot 2
each + PORT_STRIDE, and so on (``raf sim --help`` shows the numbers).
The factory-state server is one (robot 1's endpoints open it) and sees every robot; there is no control
channel with several robots (sim/control.py drives one robot). Instead each robot's Command datagrams may
carry SimTwo's teleport labels (simtwo/teleport.py, docs/protocol.md), applied as simtwo/control.pas does
(each TpId once): no TpTarget moves that robot (at rest, magnet released), ``PartN`` moves part N. So the
bridges' ``sim/set_robot_pose``, ``sim/place_part`` and ``sim/reset`` (robot only) work per robot, as with
SimTwo.

Each cycle: every robot's command socket is drained (lockstep: the replies awaited in turn, robot 1
first), the scene advances once (:meth:`Simulator.step_all`), every robot's camera frames are published,
then every robot's SensorFrame is sent. Each robot's command handling (one controller, command timeout,
lockstep timeout policy, counters) is a :class:`~robotatfactory.sim.runner.SimRunner`'s, per robot.
"""
from __future__ import annotations

import dataclasses
import sys
import threading
import time

from ..errors import ConfigError
from ..simtwo import ProtocolError
from ..simtwo.teleport import Teleport, plate_facing
from .runner import RunnerConfig, RunResult, SimRunner

PORT_STRIDE = 10  # robot k's ports: robot 1's + PORT_STRIDE * (k - 1)


def _shift_endpoint(endpoint: str, offset: int) -> str:
    """``tcp://host:port`` with the port moved by ``offset``; ConfigError when it has no numeric port."""
    head, sep, port = endpoint.rpartition(":")
    if not sep or not port.isdigit():
        raise ConfigError(f"camera endpoint {endpoint!r}: several robots need a tcp://HOST:PORT endpoint "
                          "(robot k's port is derived from it)")
    return f"{head}:{int(port) + offset}"


def robot_ports(config: RunnerConfig, k: int) -> RunnerConfig:
    """Robot ``k``'s (1-based) endpoints derived from robot 1's ``config``: command port, bridge port and
    camera port + ``PORT_STRIDE * (k - 1)``; the factory server and the control channel only for robot 1.
    A command port of 0 (any free port) stays 0."""
    if k == 1:
        return dataclasses.replace(config, control_port=None)
    off = PORT_STRIDE * (k - 1)
    port = config.port + off if config.port else 0
    for name, p in (("command port", port), ("bridge port", config.bridge[1] + off)):
        if not 0 <= p <= 65535:
            raise ConfigError(f"robot {k}'s {name} {p} is out of range: choose lower base ports")
    return dataclasses.replace(
        config, port=port, bridge=(config.bridge[0], config.bridge[1] + off),
        camera_bind=_shift_endpoint(config.camera_bind, off) if config.camera_bind else None,
        server_port=None, control_port=None, start_paused=False, quiet=True, status_every=0.0)


class UnitRunner(SimRunner):
    """One robot's endpoints in a :class:`MultiRunner`: a :class:`SimRunner` that also applies the teleport
    labels of the Commands it accepts (SimTwo's, see the module docstring)."""

    def __init__(self, sim, config: RunnerConfig | None = None, *, out=None):
        super().__init__(sim, config, out=out)
        self._last_teleport: int | None = None
        self.teleports = 0

    def _accept(self, data: bytes, addr, expect_seq: int | None) -> bool:
        before = self.counters.commands
        got = super()._accept(data, addr, expect_seq)
        if self.counters.commands != before:  # a valid command from the controller
            try:
                tp = Teleport.from_datagram(data)
            except (ProtocolError, ValueError) as e:
                self._rlog.warn("rx-teleport", f"teleport labels from {addr[0]}:{addr[1]} ignored: {e}")
                return got
            if tp is not None and tp.id != self._last_teleport:
                self._last_teleport = tp.id
                self._teleport(tp)
        return got

    def _teleport(self, tp: Teleport) -> None:
        sim = self.sim
        target = tp.target
        if not target:
            sim.set_pose(tp.x, tp.y, tp.theta)
        elif target.startswith("Part") and target[4:].isdigit() and int(target[4:]) in sim.parts.qadr:
            # TpTh is SimTwo's heading of the part (the plate's + pi/2); place_part takes the plate's
            sim.place_part(int(target[4:]), tp.x, tp.y, plate_facing(tp.theta))
        else:
            self._rlog.warn("teleport-target", f"teleport {tp.id}: unknown target {target!r} ignored (no TpTarget: "
                                               "this robot; Part1..N: a part)")
            return
        self.teleports += 1


class MultiRunner:
    """Runs a :class:`~robotatfactory.sim.Simulator` of several robots (``sim.units``) against the outside
    world: one :class:`SimRunner` per robot for its endpoints and commands. See the module docstring."""

    def __init__(self, sim, config: RunnerConfig | None = None, *, out=None):
        if len(sim.units) < 2:
            raise ConfigError("MultiRunner runs a scene of several robots (use SimRunner for one)")
        config = config or RunnerConfig()
        if config.start_paused:
            raise ConfigError("--paused needs the control channel, which runs with one robot only")
        self.sim = sim
        self.config = config
        self.out = out if out is not None else sys.stdout
        self.runners = [UnitRunner(u, robot_ports(config, k), out=self.out) for k, u in enumerate(sim.units, 1)]
        self._stop = threading.Event()

    def open(self) -> "MultiRunner":
        try:
            for r in self.runners:
                r.open()
        except Exception:
            self.close()
            raise
        return self

    def close(self) -> None:
        for r in self.runners:
            r.close()

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()

    @property
    def server(self):
        return self.runners[0].server

    def request_stop(self, *_args) -> None:
        """Ask the loop to end after the present cycle (signal-handler safe)."""
        self._stop.set()
        for r in self.runners:
            r.request_stop()

    def describe(self) -> list[str]:
        """One line per robot: its command port, where its frames go and its camera endpoint."""
        out = []
        for k, r in enumerate(self.runners, 1):
            host, port = r.address
            c = r.config
            cam = c.camera_bind or "no camera"
            out.append(f"robot {k}: commands on udp {host}:{port}, frames to udp {c.bridge[0]}:{c.bridge[1]}, "
                       f"camera {cam}, start pose ({r.sim.pose[0]:.3f}, {r.sim.pose[1]:.3f}, "
                       f"{r.sim.pose[2]:.3f})")
        return out

    def status_line(self, wall_elapsed: float) -> str:
        sim = self.sim
        rtf = sim.time / wall_elapsed if wall_elapsed > 0 else 0.0
        rep = self.runners[0].report()
        parts = [f"t={sim.time:8.2f}s rtf {rtf:5.2f}x"]
        for k, r in enumerate(self.runners, 1):
            held = f" part {r.sim.held}" if r.sim.held is not None else ""
            parts.append(f"r{k} sent {r.counters.frames_sent} cmd {r.counters.commands} "
                         f"V={r.command.v:+.2f} W={r.command.w:+.2f}{held}")
        return " | ".join(parts) + (f" | {rep.short()}" if rep is not None else "")

    def run(self) -> list[RunResult]:
        """Run until the duration, a stop request or a lockstep ``exit`` of any robot; one result per robot."""
        c = self.config
        runners = self.runners
        self.open()
        reason, code = "stopped", 0
        wall0 = time.monotonic()
        sim = self.sim
        sim0 = sim.time
        for r in runners:
            r._pace0 = (wall0, sim0)
        next_status = wall0 + c.status_every
        try:
            while not self._stop.is_set():
                if c.duration is not None and sim.time - sim0 >= c.duration - 1e-9:
                    reason = "duration"
                    break
                for r in runners:
                    r._check_command_age()
                frames = sim.step_all([r.command for r in runners])
                for r, f in zip(runners, frames):
                    r._stepped(f)
                    r._publish(r.sim.take_frames())
                runners[0]._pace(sim.time)
                if not c.lockstep:  # the script calls, as SimRunner's: the replies so far, then the frames
                    readable = sim.replies_readable()  # one GUI loop for the whole scene
                    for r in runners:
                        if readable:
                            r._drain(first_wins=sim.config.reply_timing == "simtwo")
                        else:
                            r.counters.replies_deferred += 1
                for r, f in zip(runners, frames):
                    r._send(f)
                if c.lockstep:
                    for r, f in zip(runners, frames):
                        if not r._wait_reply(f.seq):
                            if self._stop.is_set():
                                break
                            if not r._on_timeout(f.seq):
                                reason, code = "timeout-exit", 3
                                self._stop.set()
                                break
                now = time.monotonic()
                if not c.quiet and c.status_every > 0 and now >= next_status:
                    print(self.status_line(now - wall0), file=self.out, flush=True)
                    next_status = now + c.status_every
        finally:
            wall = time.monotonic() - wall0
            self.close()
        return [RunResult(sim_time=sim.time - sim0, wall_time=wall, counters=r.counters.as_dict(),
                          report=r.report() if k == 0 else None, reason=reason, exit_code=code)
                for k, r in enumerate(runners)]
