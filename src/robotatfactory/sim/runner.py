"""``SimRunner``: the stand-in simulator's endpoints and pacing (what ``raf sim`` runs).

Each control cycle (40 ms of simulation time):

1. drain the command socket without blocking; the latest valid :class:`Command` wins (malformed and foreign
   datagrams are counted and logged, rate-limited, with the sender and the reason; the last valid command
   stays in force). Commands come from one controller: the configured ``controller`` address or the first
   that sends a valid command; another source is ignored and counted (``foreign_source``) until the
   controller has been silent for ``takeover_after`` wall seconds. With no valid command for
   ``command_timeout`` simulation seconds the robot stops (V = W = 0, magnet kept), as SimTwo's
   ``control.pas`` does (``COMMAND_TIMEOUT_MS``);
2. ``Simulator.step_cycle`` with that command;
3. publish the camera frames rendered during the cycle (ZMQ PUB, raw B G R A bottom-up, SNDHWM 2) --
   before step 4, which is the frame ordering rule of docs/dev/interfaces.md; ``realtime`` with the
   default ``camera_timing="simtwo"`` publishes each one when its simulation time has come on the wall
   clock, as SimTwo's GUI loop sends a frame as soon as it is rendered (``fast``, and the ``"grid"``
   idealisation, publish them together just before the SensorFrame);
4. send the cycle's :class:`SensorFrame` to the bridge, from the command socket (so the bridge replies to
   the frame's source address) -- ``realtime``: when its simulation time has come, as SimTwo's script
   sends it, so a reply is read in the next cycle, as in SimTwo;
5. with ``lockstep``, wait for the reply (the Command whose Seq is the frame's) up to ``lockstep_timeout``
   wall seconds; on timeout apply the policy: ``stop`` (V = W = 0, magnet kept), ``hold`` (keep the last
   command) or ``exit`` (end the run) -- always with a (rate-limited) warning, never a silent hang;
6. pace: ``realtime`` sleeps (in steps 3 and 4) so simulation time follows the wall clock, ``fast`` does
   not.

``paced`` (issue 23): as fast as the controller answers, with the free-running loop's timing. After sending
frame k the runner waits (up to ``lockstep_timeout``, then the timeout policy) for the reply to frame k, but
holds it back and applies it in the next cycle's script call (step 1 of cycle k + 1, where a free-running
run reads it), so the command answering frame k acts during (t(k+1), t(k+2)] exactly as in real time:
the loop keeps its latency in control cycles and no reply is ever late. The reply-reading model
(``replies_readable``, SimTwo's GUI loop) still applies: a held reply waits for a cycle that reads
replies. With ``lockstep`` by contrast the reply to frame k acts during (t(k), t(k+1)], a cycle earlier.

SIGINT/SIGTERM (through :meth:`request_stop`) end the run after the current cycle; ``run`` returns a
:class:`RunResult` with the counters and the referee's report.
"""
from __future__ import annotations

import gc
import logging
import math
import select
import socket
import sys
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..ratelog import RateLimitedLog
from ..simtwo import Command, ProtocolError
from ..simtwo.camera import camera_header
from ..simtwo.labels import format_real
from ..simtwo.messages import (LIDAR_SEPARATOR, PROTOCOL_VERSION, VERSION_LABEL, decode_link_lost, encode_parts,
                               encode_ranges)
from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SERVER_UDP_PORT, SIMTWO_UDP_PORT, bind_udp

log = logging.getLogger(__name__)

TIMEOUT_POLICIES = ("stop", "hold", "exit")
MODES = ("realtime", "fast", "paced")
RECV_BUFFER = 65535
MAX_BEHIND = 0.25  # s: a realtime run further behind the wall clock than this stops trying to catch up
PACED_SUBSCRIBER_WAIT = 30.0  # wall s a paced run waits for a camera subscriber before its first frame

@dataclass(frozen=True)
class RunnerConfig:
    """Addresses, pacing and the lockstep policy. Seconds are wall-clock seconds unless said otherwise."""

    host: str = LOCALHOST
    port: int = SIMTWO_UDP_PORT
    bridge: tuple[str, int] = (LOCALHOST, BRIDGE_UDP_PORT)
    camera_bind: str | None = f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}"  # None: no camera stream
    server_host: str = LOCALHOST
    server_port: int | None = SERVER_UDP_PORT  # None: no factory-state server
    mode: str = "realtime"
    lockstep: bool = False
    lockstep_timeout: float = 1.0
    on_timeout: str = "stop"
    duration: float | None = None  # simulation seconds; None: until stopped
    status_every: float = 1.0
    quiet: bool = False
    log_period: float = 5.0  # rate limit of repeated warnings
    controller: tuple[str, int] | None = None  # the only source of commands; None: the first valid sender
    takeover_after: float = 2.0  # wall s the controller must be silent before another source may take over
    #: simulation s without a valid command before the robot stops, as control.pas's COMMAND_TIMEOUT_MS (400);
    #: None: keep the last command forever (an idealisation: SimTwo's script has no such mode)
    command_timeout: float | None = 0.4
    control_port: int | None = None  # the control channel's UDP port on host (sim/control.py); None: none
    start_paused: bool = False  # start paused (the control channel's step/resume run it)
    control_optional: bool = False  # True: a control port that cannot be bound is a warning, not an error
    trace: str | None = None  # write the ground-truth trace here (sim/trace.py); None: none
    end_after_max: float | None = None  # simulation s after the maximum score was reached: end the run
    #: paced: script calls a reply waits before it is applied: 1, as free-running (a controller that answers
    #: frame n with what it decided earlier, e.g. a bridge replying at once); 2 for a controller that answers
    #: frame n with its decision on frame n (the paced whole stack: then the loop is real time's)
    pace_hold: int = 1

    def __post_init__(self):
        if self.mode not in MODES:
            raise ConfigError(f"mode {self.mode!r}: choose one of {', '.join(MODES)}")
        if not (isinstance(self.pace_hold, int) and 1 <= self.pace_hold <= 10):
            raise ConfigError(f"--pace-hold {self.pace_hold!r}: expected a whole number of cycles, 1..10")
        if self.mode == "paced" and self.lockstep:
            raise ConfigError("--paced waits for every reply and applies it a cycle later, as free-running; "
                              "--lockstep applies it at once: choose one")
        if self.on_timeout not in TIMEOUT_POLICIES:
            raise ConfigError(f"--on-timeout {self.on_timeout!r}: choose one of {', '.join(TIMEOUT_POLICIES)}")
        if not (self.lockstep_timeout > 0 and math.isfinite(self.lockstep_timeout)):
            raise ConfigError(f"--lockstep-timeout {self.lockstep_timeout}: must be a positive number of seconds")
        if self.command_timeout is not None and not (self.command_timeout > 0 and math.isfinite(self.command_timeout)):
            raise ConfigError(f"--command-timeout {self.command_timeout}: must be a positive number of simulation "
                              "seconds")
        if not (self.takeover_after >= 0 and math.isfinite(self.takeover_after)):
            raise ConfigError(f"--takeover-after {self.takeover_after}: must be >= 0 seconds")
        if self.end_after_max is not None and not (self.end_after_max >= 0 and math.isfinite(self.end_after_max)):
            raise ConfigError(f"--end-after-max {self.end_after_max}: must be >= 0 simulation seconds")
        if self.duration is not None and not (self.duration > 0 and math.isfinite(self.duration)):
            raise ConfigError(f"--duration {self.duration}: must be a positive number of simulation seconds")
        for name, port in (("--port", self.port), ("--bridge port", self.bridge[1]),
                           ("--control-port", self.control_port if self.control_port is not None else 0),
                           ("--server-port", self.server_port if self.server_port is not None else 0)):
            if not (isinstance(port, int) and 0 <= port <= 65535):
                raise ConfigError(f"{name} {port!r}: must be an integer 0..65535")


def parse_address(text: str, default_host: str = LOCALHOST) -> tuple[str, int]:
    """``host:port`` or ``port`` to a tuple; ConfigError on anything else."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = default_host, text
    try:
        p = int(port)
    except ValueError:
        raise ConfigError(f"address {text!r}: expected host:port with a numeric port") from None
    if not 0 <= p <= 65535:
        raise ConfigError(f"address {text!r}: port must be 0..65535")
    return host or default_host, p


class CachedFrameEncoder:
    """``SensorFrame.encode`` with the LIDAR field formatted incrementally.

    A 40 ms cycle refreshes 72 of 360 rays; formatting all 360 with ``%.6g`` every cycle was the runner's
    largest cost. The bytes are identical to ``frame.encode()`` (a test checks it).
    """

    # SensorFrame.encode's labels in its order; every value is a plain number or the LIDAR list
    _TEMPLATE = "\r\n\r\n".join(f"{label}\r\n%s" for label in (
        VERSION_LABEL, "Seq", "Tms", "Enc1", "Enc2", "Odo1", "Odo2", "X", "Y", "Theta", "Contact", "Magnet",
        "LidarN", "Lidar")) + "\r\n\r\n"

    def __init__(self):
        self._last = None
        self._strings: list[str] = []

    def _ranges(self, ranges: np.ndarray) -> str:
        last = self._last
        if last is None or last.shape != ranges.shape:
            self._strings = encode_ranges(ranges).split(LIDAR_SEPARATOR) if len(ranges) else []
        else:
            changed = np.flatnonzero(ranges != last)  # (ranges are never NaN: -1 marks no return)
            if len(changed):
                fresh = encode_ranges(ranges[changed]).split(LIDAR_SEPARATOR)
                strings = self._strings
                for i, v in zip(changed.tolist(), fresh):
                    strings[i] = v
        self._last = ranges.copy()
        return LIDAR_SEPARATOR.join(self._strings)

    def encode(self, frame) -> bytes:
        ranges = np.asarray(frame.ranges, dtype=np.float64)
        text = self._TEMPLATE % (
            PROTOCOL_VERSION, int(frame.seq), int(frame.time_ms), int(frame.enc_delta[0]), int(frame.enc_delta[1]),
            int(frame.enc_total[0]), int(frame.enc_total[1]), format_real(frame.x), format_real(frame.y),
            format_real(frame.theta), int(frame.contact), int(frame.magnet), len(ranges), self._ranges(ranges))
        if frame.parts:  # the optional labels, after the LIDAR as SensorFrame.encode writes them
            text += f"PartsN\r\n{len(frame.parts)}\r\n\r\nParts\r\n{encode_parts(frame.parts)}\r\n\r\n"
        if frame.camera_frames is not None:
            text += f"CamN\r\n{int(frame.camera_frames)}\r\n\r\n"
        return text.encode("ascii")



def _malloc_trim() -> None:
    """Give the C heap's free memory back to the system (glibc's ``malloc_trim``; nothing elsewhere): a freed
    scene's MuJoCo arrays leave holes that the next scene does not always fit, and the resident memory crept
    up by steps over the resets without it."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass

@dataclass
class RunnerCounters:
    cycles: int = 0
    frames_sent: int = 0
    send_errors: int = 0
    commands: int = 0  # valid commands received
    applied: int = 0  # cycles that got a new valid command (reply_timing simtwo: at most one per script call)
    replies_deferred: int = 0  # script calls that could not read (a GUI catch-up turn's later calls)
    superseded: int = 0  # valid commands read in one call with another that won (simtwo: the first; else the newest)
    replies: int = 0  # frames answered: a valid command with the Seq of the frame awaited (a duplicate not again)
    stale: int = 0  # valid commands whose Seq was not acceptable (control.pas's SeqAcceptable): never applied
    rejected: int = 0  # malformed + foreign + version
    malformed: int = 0
    foreign: int = 0
    version: int = 0
    timeouts: int = 0
    foreign_source: int = 0  # datagrams from a source other than the controller (not decoded)
    takeovers: int = 0  # another source took over after the controller fell silent
    command_timeouts: int = 0  # times the robot was stopped for want of a valid command
    camera_frames: int = 0
    camera_errors: int = 0
    link_lost: int = 0  # paced: frames, or their replies, a lossy link said it lost (LINK_LOST): not waited for

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class RunResult:
    sim_time: float
    wall_time: float
    counters: dict
    report: object | None  # competition ScoreReport, None without the competition
    reason: str  # duration, stopped, timeout-exit
    exit_code: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else math.inf


class SimRunner:
    """Runs a :class:`~robotatfactory.sim.Simulator` against the outside world. See the module docstring."""

    def __init__(self, sim, config: RunnerConfig | None = None, *, out=None):
        self.sim = sim
        self.config = config or RunnerConfig()
        self.out = out if out is not None else sys.stdout
        self.counters = RunnerCounters()
        self._rlog = RateLimitedLog(log, self.config.log_period)
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._zmq_ctx = None
        self._pub = None
        self.server = None
        self.command = Command.stop()
        self._first_wins = self._applied_here = self._decided_here = False  # one script call's reading (_read)
        #: paced: the replies received, each with the Seq of the last frame sent before it came; the script call
        #: before frame n applies those of frames <= n - pace_hold (None: not paced)
        self._held: list[tuple[int, Command]] | None = [] if self.config.mode == "paced" else None
        self._last_applied = -1  # the Seq of the last reply applied (-1: none, or only unsolicited ones)
        self._frame_seq = -1  # the Seq of this cycle's frame (the newest a reply may answer)
        self._answered = -1  # the Seq of the last frame counted as answered (``replies``)
        self._last_sent = -1
        self._encoder = CachedFrameEncoder()
        self._pace0 = (time.monotonic(), 0.0)  # (wall, simulation) times pacing counts from; set by run()
        self._opened = False
        self.controller: tuple[str, int] | None = self.config.controller
        self._controller_seen: float | None = None  # wall (monotonic) time of its last valid command
        self._command_sim_time: float | None = None  # simulation time of the last valid command
        from .control import SimControl

        self.control = SimControl(self)  # reset/pause/step/... requests (sim/control.py)
        self.control.paused = self.config.start_paused
        self._ctl_sock: socket.socket | None = None
        self._trace = None  # sim/trace.py TraceWriter while open with --trace
        self._collect = False  # a reset replaced the scene: collect the old one (run())
        self._max_at: float | None = None  # simulation time the maximum score was first seen

    # ------------------------------------------------------------------------------------------ setup
    def open(self) -> "SimRunner":
        """Bind the command socket, the camera publisher and the factory-state server."""
        if self._opened:
            return self
        c = self.config
        sock = bind_udp(socket.socket(socket.AF_INET, socket.SOCK_DGRAM), c.host, c.port, "the command socket",
                        "another simulator running? choose --port")
        sock.setblocking(False)
        self._sock = sock
        try:
            if c.control_port is not None:
                try:
                    ctl = bind_udp(socket.socket(socket.AF_INET, socket.SOCK_DGRAM), c.host, c.control_port,
                                   "the control channel", "another simulator running? choose --control-port")
                except ConfigError as e:
                    if not c.control_optional:
                        raise
                    log.warning("%s; running without a control channel", e)
                else:
                    ctl.setblocking(False)
                    self._ctl_sock = ctl
            if c.camera_bind:
                import zmq

                self._zmq_ctx = zmq.Context()
                # paced: XPUB, which hears subscriptions, so the first frame waits for the camera side (a PUB
                # drops what it sends before a subscriber has joined, and a paced loop would wait for it)
                pub = self._zmq_ctx.socket(zmq.PUB if c.mode != "paced" else zmq.XPUB)
                # paced: the loop waits for the camera side, so a deeper queue never fills; it must not drop
                pub.setsockopt(zmq.SNDHWM, 2 if c.mode != "paced" else 32)
                pub.setsockopt(zmq.LINGER, 0)
                try:
                    pub.bind(c.camera_bind)
                except zmq.ZMQError as e:
                    pub.close()
                    raise ConfigError(f"cannot bind the camera publisher {c.camera_bind}: {e} "
                                      "(choose --camera-bind or --no-camera)") from None
                self._pub = pub
            if c.server_port is not None and self.sim.factory is not None:
                from ..competition import FactoryServer

                sim = self.sim
                self.server = FactoryServer(sim.factory, host=c.server_host, port=c.server_port,
                                            clock=lambda: sim.time).start()
            if c.trace:
                from .trace import TraceWriter

                self._trace = TraceWriter(c.trace, self.sim)
        except Exception:
            self.close()
            raise
        self._opened = True
        return self

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the command socket is bound to (the real port when configured with 0)."""
        return self._sock.getsockname()[:2] if self._sock is not None else (self.config.host, self.config.port)

    @property
    def control_address(self) -> tuple[str, int] | None:
        """(host, port) of the control channel, None without one."""
        return self._ctl_sock.getsockname()[:2] if self._ctl_sock is not None else None

    def close(self) -> None:
        if self._trace is not None:
            self._trace.close()
            self._trace = None
        if self._ctl_sock is not None:
            self._ctl_sock.close()
            self._ctl_sock = None
        if self.server is not None:
            self.server.stop()
            self.server = None
        if self._pub is not None:
            self._pub.close(0)
            self._pub = None
        if self._zmq_ctx is not None:
            self._zmq_ctx.term()
            self._zmq_ctx = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        self._opened = False

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------------------------------ control
    def replace_sim(self, new_sim) -> None:
        """A reset (sim/control.py): run ``new_sim`` from the next cycle on, as a fresh start would (the
        command in force, its age, the frame encoder, the pacing and the factory server follow)."""
        old, self.sim = self.sim, new_sim
        old.close()
        self.command = Command.stop()
        self._command_sim_time = None
        self._encoder = CachedFrameEncoder()
        self._pace0 = (time.monotonic(), new_sim.time)
        # Seq starts again at 0: a reply to the old scene's frames is newer than the new frames, so never acts
        self._last_applied = self._frame_seq = self._last_sent = self._answered = -1
        if self._held is not None:  # paced: nor do the ones held back
            self._held.clear()
        if self.server is not None and new_sim.factory is not None:
            self.server.factory = new_sim.factory
            self.server.clock = lambda: self.sim.time
        self._collect = True  # run() collects the old scene once nothing refers to it any more

    def _collect_old_scene(self) -> None:
        """After a reset: the old scene (about 16 MB with its MuJoCo model and data) is held only by its own
        reference cycles (units, generators), which wait for Python's rare generation-2 collections: the
        resident memory grew at every reset (the realtime soak, issue 22: +100 MB in six rounds). A full
        collection once the loop has let go of it; its time is not owed as lateness."""
        self._collect = False
        gc.collect()
        _malloc_trim()
        self._pace0 = (time.monotonic(), self.sim.time)

    def on_resume(self) -> None:
        """Pacing counts from now on (a paused run is not behind the wall clock)."""
        self._pace0 = (time.monotonic(), self.sim.time)

    def _ctl_reply(self, reply: dict, addr) -> None:
        from .control import encode_reply

        try:
            self._ctl_sock.sendto(encode_reply(reply), addr)
        except (OSError, ValueError) as e:
            self._rlog.warn("ctl-tx", f"control reply to {addr} not sent: {e}")

    def _poll_control(self) -> None:
        """Apply every queued control request (between cycles: never during one)."""
        sock = self._ctl_sock
        if sock is None:
            return
        while True:
            try:
                data, addr = sock.recvfrom(RECV_BUFFER)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as e:
                self._rlog.warn("ctl-rx", f"control socket receive error: {e}")
                return
            try:
                reply = self.control.handle(data, addr)
            except Exception as e:  # noqa: BLE001 - a request must never end the run
                log.exception("control request failed")
                from .control import error_reply

                reply = error_reply(None, None, "internal", repr(e))
            if reply is not None:
                if not reply["ok"]:
                    self._rlog.warn(f"ctl-{reply['error']}", f"control request from {addr[0]}:{addr[1]} "
                                                             f"rejected: {reply['error']}: {reply['message']}")
                self._ctl_reply(reply, addr)

    def _wait_paused(self) -> None:
        """Paused: wait (<= 0.1 s) for a control request, keeping the command socket drained."""
        socks = [s for s in (self._ctl_sock, self._sock) if s is not None]
        try:
            select.select(socks, [], [], 0.1)
        except (InterruptedError, ValueError):
            pass
        if not self.config.lockstep:
            self._drain()

    def request_stop(self, *_args) -> None:
        """Ask the loop to end after the present cycle (signal-handler safe)."""
        self._stop.set()

    # ------------------------------------------------------------------------------------------ commands
    def _accept(self, data: bytes, addr, expect_seq: int | None) -> bool:
        """Decode one datagram; returns True when it is the reply to ``expect_seq``."""
        c = self.counters
        src = (addr[0], addr[1])
        now = time.monotonic()
        foreign = self.controller is not None and src != self.controller
        if foreign and (self.config.controller is not None or self._controller_seen is None
                        or now - self._controller_seen < self.config.takeover_after):
            c.foreign_source += 1
            c.rejected += 1
            self._rlog.warn("rx-foreign-source", f"ignoring a datagram from {src[0]}:{src[1]}: commands come from "
                                                 f"{self.controller[0]}:{self.controller[1]} (another controller "
                                                 f"sending to port {self.address[1]}?)")
            return False
        lost = decode_link_lost(data) if self._held is not None else None  # paced: the link lost a frame/reply
        if lost is not None:
            c.link_lost += 1
            return lost == expect_seq  # (the command stays: as in real time, a cycle with no reply keeps it)
        try:
            cmd = Command.decode(data)
        except (ProtocolError, UnicodeDecodeError, ValueError) as e:
            msg = str(e)
            c.rejected += 1
            if msg.startswith("not a RobotAtFactory"):
                c.foreign += 1
                kind = "foreign"
            elif "protocol version" in msg:
                c.version += 1
                kind = "version"
            else:
                c.malformed += 1
                kind = "malformed"
            self._rlog.warn(f"rx-{kind}", f"rejected {kind} command datagram ({len(data)} bytes) from "
                                          f"{addr[0]}:{addr[1]}: {msg}; keeping V={self.command.v:g} "
                                          f"W={self.command.w:g} S={int(self.command.magnet)}")
            return False
        if self.controller != src:
            if self.controller is not None:
                c.takeovers += 1
                log.warning("controller %s:%d silent for %.1f s: commands now come from %s:%d", *self.controller,
                            now - self._controller_seen, *src)
            self.controller = src
        self._controller_seen = now
        c.commands += 1
        if self._held is not None:  # paced: applied in a later script call (_apply_held)
            # held as the reply to the frame it names (else the frame sent last): one that a lossy link let
            # through after its notice, once the next frame was out, acts as if in time, whatever the timing
            self._held.append((cmd.seq if cmd.seq >= 0 else self._last_sent, cmd))
        else:
            self._read(cmd)
        if expect_seq is not None and cmd.seq == expect_seq:
            if self._answered != expect_seq:
                c.replies += 1
                self._answered = expect_seq
            return True
        return False

    def _stepped(self, frame) -> None:
        """A cycle ran and made ``frame``: counted, and replies may now answer it."""
        self.counters.cycles += 1
        self._frame_seq = frame.seq

    def _seq_acceptable(self, seq: int) -> bool:
        """control.pas's ``SeqAcceptable``: a reply acts if its Seq is -1 (unsolicited) or newer than the last
        reply applied and not newer than this cycle's frame (a duplicate, a reply a lossy link held back behind
        a newer one, or one to a frame of an earlier run, does not)."""
        return seq == -1 or self._last_applied < seq <= self._frame_seq

    def _read(self, cmd: Command) -> None:
        """One valid command read in this script call. With ``first_wins`` (SimTwo's reply timing) the first
        of the call decides, as control.pas reads the first occurrence of each label of what ``ReadUDPData``
        concatenated: if its Seq is not acceptable the call applies nothing. Otherwise each acceptable one
        acts in turn (the newest stays)."""
        c = self.counters
        if self._first_wins and self._decided_here:
            c.superseded += 1
            return
        self._decided_here = True
        if not self._seq_acceptable(cmd.seq):
            c.stale += 1
            self._rlog.warn("rx-stale", f"command Seq {cmd.seq} ignored: not newer than the last applied "
                                        f"({self._last_applied}) or newer than the frame sent ({self._frame_seq})")
            return
        if cmd.seq >= 0:
            self._last_applied = cmd.seq
        self._command_sim_time = self.sim.time
        if self._applied_here:
            c.superseded += 1  # (the one applied before it in this call)
        else:
            c.applied += 1
        self._applied_here = True
        self.command = cmd

    def _check_command_age(self) -> None:
        """No valid command for more than ``command_timeout`` simulation seconds: stop the wheels (magnet kept).
        Checked before each cycle, as control.pas does at each script call (``TimeMs - LastValidMs >
        COMMAND_TIMEOUT_MS``): the first cycle that starts more than the timeout after the last valid command
        runs with V = W = 0 (0.44 s after it with 0.4 s and 40 ms cycles, as SimTwo; it stopped one cycle
        earlier before issue 19's faults run on SimTwo). The timeout was 0.5 s until issue 22: the wheels take
        another 0.08 s to stop, so the robot was at rest 0.6-0.66 s after its controller died."""
        t = self.config.command_timeout
        if t is None or self._command_sim_time is None:
            return
        if self.sim.time - self._command_sim_time <= t + 1e-9:
            return
        if self.command.v or self.command.w:
            self.counters.command_timeouts += 1
            self._rlog.warn("command-timeout", f"no valid command for {self.sim.time - self._command_sim_time:.2f} "
                                               f"s of simulation time (> {t:g} s by the end of this cycle): "
                                               "stopping the robot (V = W = 0, magnet kept)")
            self.command = Command(0.0, 0.0, self.command.magnet, -1)

    def _drain(self, expect_seq: int | None = None, first_wins: bool = False) -> bool:
        """Read every queued datagram; True if the reply to ``expect_seq`` was among them. ``first_wins``: of
        several valid commands, the first is applied (SimTwo: ReadUDPData concatenates them and control.pas
        takes each label's first occurrence); the others are counted in ``superseded``."""
        got = False
        sock = self._sock
        self._first_wins, self._applied_here, self._decided_here = first_wins, False, False
        while True:
            try:
                data, addr = sock.recvfrom(RECV_BUFFER)
            except (BlockingIOError, InterruptedError):
                return got
            except OSError as e:  # e.g. ICMP port unreachable reported on some systems: not fatal
                self._rlog.warn("rx-error", f"command socket receive error: {e}")
                return got
            if self._accept(data, addr, expect_seq):
                got = True

    def _apply_held(self, seq: int, first_wins: bool) -> None:
        """Paced: the script call before frame ``seq`` reads the replies held back by ``_accept`` that came
        before frame ``seq - pace_hold + 1`` was sent: the first of them with SimTwo's reply timing
        (``first_wins``), else the newest."""
        self._drain()  # anything else queued (held as well)
        limit = seq - self.config.pace_hold
        due = [c for n, c in self._held if n <= limit]
        if not due:
            return
        self._held[:] = [(n, c) for n, c in self._held if n > limit]
        self._first_wins, self._applied_here, self._decided_here = first_wins, False, False
        for cmd in due:  # in the order they came, as ReadUDPData concatenates them
            self._read(cmd)

    def _wait_reply(self, seq: int) -> bool:
        """Lockstep: wait up to the timeout for the Command answering frame ``seq``."""
        deadline = time.monotonic() + self.config.lockstep_timeout
        if self._drain(seq):
            return True
        while not self._stop.is_set():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            try:
                r, _, _ = select.select([self._sock], [], [], min(left, 0.1))
            except InterruptedError:
                continue
            if r and self._drain(seq):
                return True
        return False

    def _on_timeout(self, seq: int) -> bool:
        """Apply the lockstep timeout policy; returns False when the run must end."""
        c = self.config
        self.counters.timeouts += 1
        if c.on_timeout == "exit":
            log.error("lockstep: no reply to frame %d within %.3g s; --on-timeout exit: ending the run", seq,
                      c.lockstep_timeout)
            return False
        if c.on_timeout == "stop":
            self.command = Command(0.0, 0.0, self.command.magnet, -1)
            what = "stopping the robot (V = W = 0, magnet kept)"
        else:
            what = f"holding the last command V={self.command.v:g} W={self.command.w:g}"
        self._rlog.warn("timeout", f"lockstep: no reply to frame {seq} within {c.lockstep_timeout:g} s from the "
                                   f"controller at {self.config.bridge[0]}:{self.config.bridge[1]}; {what} "
                                   f"({self.counters.timeouts} timeouts so far)")
        return True

    # ------------------------------------------------------------------------------------------ outputs
    def _pace(self, t: float) -> None:
        """``realtime``: wait until simulation time ``t`` (s) is due on the wall clock; re-anchor the pacing
        when more than ``MAX_BEHIND`` late (lockstep waits, a slow machine). ``fast``: return at once."""
        if self.config.mode != "realtime" or self.control.paused:  # steps of a paused run: at once
            return
        w0, s0 = self._pace0
        now = time.monotonic()
        ahead = (t - s0) - (now - w0)
        if ahead > 0:
            self._stop.wait(ahead)
        elif -ahead > MAX_BEHIND:
            self._pace0 = (now, t)

    def _publish(self, frames) -> None:
        if not frames:
            return
        bottom_up = self.sim.robot.camera.bottom_up
        paced = self.sim.config.camera_timing == "simtwo"
        if not paced:  # realtime: together, just before the SensorFrame (at its time)
            self._pace(self.sim.time)
        for f in frames:
            if self._pub is None:
                continue
            if paced:  # realtime: sent when rendered, as SimTwo's GUI does (grid: just before the SensorFrame)
                self._pace(f.time)
            try:
                import zmq

                if self._held is not None:  # paced: the frame's simulation time and index go with it
                    self._pub.send_multipart([camera_header(f.time, f.index), f.wire(bottom_up)], copy=False,
                                             flags=zmq.NOBLOCK)
                else:
                    self._pub.send(f.wire(bottom_up), copy=False, flags=zmq.NOBLOCK)
                self.counters.camera_frames += 1
            except Exception as e:  # noqa: BLE001 - a camera hiccup must not stop the simulation
                self.counters.camera_errors += 1
                self._rlog.warn("camera", f"camera frame {f.index} not published: {e}")

    def _await_camera_subscriber(self, timeout: float = PACED_SUBSCRIBER_WAIT) -> None:
        """Paced: wait (wall s) until a camera subscriber has joined, so that it gets the first frames."""
        if self._held is None or self._pub is None:
            return
        end = time.monotonic() + timeout
        while not self._stop.is_set():
            left = end - time.monotonic()
            if left <= 0:
                log.warning("paced: no camera subscriber on %s after %g s: starting without one",
                            self.config.camera_bind, timeout)
                return
            if self._pub.poll(int(min(left, 0.1) * 1000)):
                self._pub.recv()  # a subscription (b"\x01" + topic)
                return

    def _send(self, frame) -> None:
        try:
            self._sock.sendto(self._encoder.encode(frame), self.config.bridge)
            self.counters.frames_sent += 1
            self._last_sent = frame.seq
        except OSError as e:
            self.counters.send_errors += 1
            self._rlog.warn("tx", f"sensor frame {frame.seq} not sent to {self.config.bridge[0]}:"
                                  f"{self.config.bridge[1]}: {e}")

    def _max_reached(self, sim, after: float) -> bool:
        """True once the run has had its maximum score for ``after`` simulation seconds without losing it
        (checked once per simulated second, and every cycle once reached)."""
        if sim.referee is None:
            return False
        if self._max_at is None and sim.seq % max(1, round(1.0 / sim.robot.control_period)):
            return False
        rep = sim.referee.report(sim.time)
        if not rep.started or rep.points < rep.max_points:
            self._max_at = None  # not reached, or taken back (a part knocked out of its slot)
            return False
        if self._max_at is None:
            self._max_at = sim.time
        return sim.time - self._max_at >= after - 1e-9

    def report(self):
        sim = self.sim
        return sim.referee.report(sim.time) if sim.referee is not None else None

    def status_line(self, wall_elapsed: float) -> str:
        sim, c = self.sim, self.counters
        rtf = sim.time / wall_elapsed if wall_elapsed > 0 else 0.0
        rep = self.report()
        score = f" | {rep.short()}" if rep is not None else ""
        held = f" holding part {sim.held}" if sim.held is not None else ""
        return (f"t={sim.time:8.2f}s rtf {rtf:5.2f}x | sent {c.frames_sent} cmd {c.commands} applied {c.applied} "
                f"rejected {c.rejected} timeouts {c.timeouts} | camera {c.camera_frames} | "
                f"V={self.command.v:+.3f} W={self.command.w:+.3f} S={int(self.command.magnet)}{held}{score}")

    # ------------------------------------------------------------------------------------------ the loop
    def run(self) -> RunResult:
        """Run until the duration, a stop request or a lockstep ``exit``. Opens and closes the endpoints."""
        c = self.config
        self.open()
        reason, code = "stopped", 0
        wall0 = time.monotonic()
        sim0 = self.sim.time
        self._pace0 = (wall0, sim0)  # wall and simulation time that pacing counts from
        next_status = wall0 + c.status_every
        try:
            self._await_camera_subscriber()
            while not self._stop.is_set():
                self._poll_control()
                sim = self.sim  # (a reset replaces it)
                if self._collect:
                    self._collect_old_scene()
                if c.duration is not None and sim.time - sim0 >= c.duration - 1e-9:
                    reason = "duration"
                    break
                if not self.control.may_run:
                    self._wait_paused()
                    continue
                self._check_command_age()
                frame = sim.step_cycle(self.command)
                self._stepped(frame)
                if self._trace is not None:
                    self._trace.cycle(sim, frame, self.command)
                if c.end_after_max is not None and self._max_reached(sim, c.end_after_max):
                    reason = "maximum score"
                    break
                self._publish(sim.take_frames())
                self._pace(sim.time)  # realtime: the SensorFrame at its own time, after the cycle's frames
                if not c.lockstep:  # the script call, in control.pas's order: the replies so far, then the frame
                    first_wins = sim.config.reply_timing == "simtwo"
                    if not sim.replies_readable():  # (so a reply to this frame is applied in the next cycle but one)
                        self.counters.replies_deferred += 1
                    elif self._held is not None:  # paced: the replies held back for this call
                        self._apply_held(frame.seq, first_wins)
                    else:
                        self._drain(first_wins=first_wins)
                if self._held is not None:  # paced: the camera side waits for the frames published so far
                    frame.camera_frames = self.counters.camera_frames
                self._send(frame)
                done = self.control.cycle_done()
                if (c.lockstep or self._held is not None) and not self._wait_reply(frame.seq):
                    if self._stop.is_set():
                        break
                    if not self._on_timeout(frame.seq):
                        reason, code = "timeout-exit", 3
                        break
                if done is not None:  # a step request has run its cycles (replied after the lockstep reply)
                    self._ctl_reply(*done)
                now = time.monotonic()
                if not c.quiet and c.status_every > 0 and now >= next_status:
                    print(self.status_line(now - wall0), file=self.out, flush=True)
                    next_status = now + c.status_every
        finally:
            wall = time.monotonic() - wall0
            self.close()
        sim = self.sim
        return RunResult(sim_time=sim.time - sim0, wall_time=wall, counters=self.counters.as_dict(),
                         report=self.report(), reason=reason, exit_code=code)
