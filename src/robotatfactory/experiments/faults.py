"""``raf experiment faults``: the fault campaign of issue 10, on the real ``raf sim``, bridge and localization.

Everything runs on loopback (127.0.0.1) with a private roscore. Between the simulator and the bridge sits a
UDP proxy in this process (:class:`._faults_net.Proxy`): it records every SensorFrame the simulator sent (the
loss-free, fuzz-free truth) and, per part, drops, duplicates, reorders or injects datagrams. The bridge's stream
is bound to the proxy's address (its only legitimate sender).

Parts (``--parts``, all by default):

Every figure of the fuzz, loss and restart parts is the observer's (:mod:`._faults_observe`): the proxy's record
of the genuine frames against every ``odom``, ``/clock``, ``joint_states``, TF and ``scan`` message this
process's node received; a message is *poisoned* when no genuine frame supports one of its values. No figure
comes from the bridge's counters (kept beside the logs, ``bridge_diagnostics.json``) or the simulator's log.

* **fuzz**: while the robot drives (the LIDAR on), ``--fuzz-datagrams`` datagrams (default 1,000,000) go to the
  bridge's port one kind after the other, each in its own time segment: from other source addresses (a
  fuzzer process, :data:`._faults_net.FOREIGN_KINDS`, over ``--fuzz-seconds``), then a share
  (``--fuzz-inband``) from the simulator's own address through the proxy (:data:`._faults_net.INBAND_KINDS`,
  :data:`INBAND_RATE` a second), then copies of every next real frame with impossible encoder totals. Per
  kind: the sends that succeeded, those that reached the socket (minus the bridge socket's kernel drops,
  ``/proc/net/udp``) and the messages poisoned, target 0 each; 0 crashes; the odometry at every ``odom``
  message within 1 cm of the odometry over every genuine frame.
* **loss**: the proxy drops ``--drop`` (20 %), duplicates ``--dup`` (5 %) and reorders ``--reorder`` (5 %) of
  the SensorFrames and of the Commands. At every message during the loss: 0 poisoned, the heading exact, every
  ``joint_states`` on the genuine totals, the position within the chord errors of the frames the proxy did not
  deliver (:func:`._faults_observe.chord_bound`); the robot still follows cmd_vel (1 cm/s).
* **restarts**: the simulator (with its camera publisher) killed and restarted (a genuine odom and /clock of
  the new run, and images, within 1 s of its first frame; odometry on in the new run once); the bridge killed
  and restarted (from the ground truth: the wheels slowing within the command timeout (0.4 s) plus one cycle
  of the last command, the robot at rest within 0.54 s of it and 0.6 s of the kill: :func:`at_rest`; the new
  bridge's genuine odom within 1 s of its first reply); roscore killed and restarted on the same port (every node exits with a clear
  message, or keeps going: reported). 0 poisoned messages throughout.
* **soak** (:mod:`._faults_soak`, issue 22): ``--soak-minutes`` (default 60) of the whole stack as SimTwo runs
  it: ``raf sim`` free-running in real time (camera, LIDAR, factory server), the bridge, the localization and
  ``raf agent`` playing rounds one after another; memory, CPU, message rates and the loop latency in control
  cycles at the start and at the end; memory growth under 5 %, no process died.

Each figure comes with its target; ``raf experiment`` reports the ``*_target_met`` keys (it exits non-zero
when one is missed, see commands/experiment.py).

Simulator. ``--simulator standin`` (the default) runs ``raf sim``; ``--simulator simtwo`` runs the real SimTwo
(``raf simtwo run``, field ``simtwo2022``) behind the same proxy: fuzz, loss and restarts, with the keys
prefixed ``real_simtwo_``. What SimTwo cannot do (no control channel: no soak; no start pose option:
teleports; its own command timeout and log line) is in :mod:`._faults_simtwo` and in the result.

Code. This module is the campaign: the parts (:data:`PARTS`, each run in an interpreter of its own by
:func:`run_part`), the rig that starts and restarts the processes (:class:`Rig`: a private roscore and
:class:`..ros.processes.Procs`), the figures and :data:`TARGETS`, the table. The proxy and the fuzz (no ROS)
are in :mod:`._faults_net`; this process's node and what it records from the bridge (:class:`Watch`) in
:mod:`._faults_watch`; what differs on the real SimTwo in :mod:`._faults_simtwo`.
"""
from __future__ import annotations

import json
import math
import os
import random
import re
import shutil
import signal
import socket
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..sim.runner import RunnerConfig
from . import _faults_simtwo as simtwo_side
from ._faults_net import FOREIGN_KINDS, INBAND_KINDS, LOCAL, Proxy, fuzz_pool, fuzzer, udp_drops
from ._faults_observe import POSE_TOL_RAD, Geometry, Observer, chord_bound
from ._faults_soak import TARGETS as SOAK_TARGETS
from ._faults_soak import part_soak
from ._faults_watch import Watch

NAME = "faults"
HELP = ("fault campaign (issue 10): fuzz, loss, restarts and soak on the real raf sim, bridge and localization "
        "(--simulator simtwo: fuzz, loss and restarts on the real SimTwo)")
TARGETS = {
    "fuzz_crashes": "0",
    "fuzz_poisoned_messages": "0: every odom, /clock, joint_states, TF and scan message matches genuine frames "
                              "(the observer, _faults_observe)",
    **{f"fuzz_{k}_poisoned": "0" for k in (*FOREIGN_KINDS, *INBAND_KINDS, "impossible_ticks")},
    "fuzz_odometry_error_m": "<= 0.01 m at every odom message against the odometry over every genuine frame",
    "loss_poisoned_messages": "0",
    "loss_odometry_error_max_m": "<= loss_odometry_bound_m at every odom message during the loss: the chord "
                                 "errors of the frames the proxy did not deliver, at the driven speeds",
    "loss_heading_error_max_rad": "<= 1e-5 rad at every odom message (cumulative totals: no tick lost)",
    "loss_ticks_off_max": "0 at every joint_states message against the genuine totals",
    "loss_speed_error_mps": "<= 0.01 m/s (the simulator's poses: the robot follows cmd_vel)",
    "restart_poisoned_messages": "0",
    "restart_sim_odom_back_s": "<= 1 s (wall) from the restarted simulator's first frame to a genuine odom",
    "restart_sim_clock_back_s": "<= 1 s",
    "restart_sim_image_back_s": "<= 1 s",
    "restart_sim_odometry_resets": "1",
    "restart_bridge_stop_s": "<= 0.44 s (simulation) from the last command to the wheels slowing (ground truth): "
                             "the 0.4 s command timeout plus one 40 ms cycle",
    "restart_bridge_at_rest_s": "<= 0.54 s (simulation) from the last command to the robot at rest (ground truth; "
                                "issue 22's: the 0.4 s timeout, a cycle, the wheels' 0.08 s ramp)",
    "restart_bridge_at_rest_after_death_s": "<= 0.6 s (wall) from the bridge's death to the robot at rest "
                                            "(ground truth)",
    "restart_bridge_resume_s": "<= 1 s (wall) from the restarted bridge's first reply to a genuine odom",
    "restart_roscore_nodes_clear": "every node exits with a clear message (or reconnects)",
}
TARGETS.update({f"{simtwo_side.MODE}_{k}": v for k, v in list(TARGETS.items())
                if k not in simtwo_side.TARGETS_NOT_APPLICABLE})
TARGETS.update(SOAK_TARGETS)  # the stand-in only (the soak resets rounds through raf sim's control channel)
#: the simulator and mode each observed part runs in (the result's ``<part>_mode``)
OBSERVED_MODES = {p: {"standin": "raf sim --realtime: free-running in real time as SimTwo, no lockstep",
                      "simtwo": "the real SimTwo (Linux build), free-running in real time"}
                  for p in ("fuzz", "loss", "restarts")}
EXIT_STATUS_FROM_TARGETS = True  # raf experiment faults exits 1 when a target is missed
PERIOD = 0.04
#: s (simulation) from the last command to the wheels slowing: the command timeout (raf sim's, control.pas's
#: COMMAND_TIMEOUT_MS) plus one control cycle, as the script checks it at the start of each cycle
STOP_S = round(RunnerConfig.command_timeout + PERIOD, 3)


def add_arguments(parser) -> None:
    parser.add_argument("--parts", default=None,
                        help="comma-separated parts to run (default fuzz,loss,restarts,soak; with --simulator "
                             "simtwo fuzz,loss,restarts)")
    parser.add_argument("--simulator", choices=("standin", "simtwo"), default="standin", help=simtwo_side.HELP)
    parser.add_argument("--fuzz-datagrams", type=int, default=1_000_000, help="datagrams of fuzz (default 1e6)")
    parser.add_argument("--fuzz-seconds", type=float, default=60.0,
                        help="wall seconds the fuzz is spread over (default 60)")
    parser.add_argument("--fuzz-inband", type=float, default=0.05,
                        help="share of the fuzz sent from the simulator's own address (default 0.05)")
    parser.add_argument("--loss-seconds", type=float, default=20.0, help="driving time of the loss part (default 20)")
    parser.add_argument("--drop", type=float, default=0.20, help="share of datagrams dropped (default 0.20)")
    parser.add_argument("--dup", type=float, default=0.05, help="share duplicated (default 0.05)")
    parser.add_argument("--reorder", type=float, default=0.05, help="share delayed behind the next (default 0.05)")
    parser.add_argument("--no-camera-restart", action="store_true",
                        help="restart part without the camera (faster; no image figure)")
    parser.add_argument("--soak-minutes", type=float, default=60.0,
                        help="minutes of the soak, in real time (default 60)")
    parser.add_argument("--soak-sim-seconds", type=float, default=None,
                        help="seconds of the soak (overrides --soak-minutes)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the fuzz and of the proxy's choices")


# ------------------------------------------------------------------------------------------------ plumbing

def _free_udp() -> int:
    from ..ros.master import free_port

    return free_port(socket.SOCK_DGRAM)


def _wait(pred, timeout: float, what: str, check=None) -> None:
    from ..ros.processes import wait_until

    wait_until(pred, timeout, what, check, period=0.02)


# ------------------------------------------------------------------------------------------------ the rig

class Rig:
    """roscore + bridge (+ localization) + proxy + raf sim (or SimTwo), started and restarted on demand."""

    def __init__(self, args, log_dir: Path, camera: bool = False, localize: bool = False, fast: bool = False,
                 lockstep: bool = False, start_pose: str = "0.0,0.0,1.5708", lidar: bool = False):
        from ..ros.master import PrivateMaster, free_port
        from ..ros.processes import Procs

        self.args, self.camera, self.localize, self.fast, self.lockstep = args, camera, localize, fast, lockstep
        self.log_dir = log_dir
        self.lidar = lidar  # the bridge publishes scan, the proxy records the ranges (the observer checks them)
        self.start_pose = start_pose  # the open middle of the field (rules2026); the loss part drives a corridor
        self.master = PrivateMaster().start()
        self.env = self.master.env(MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
        # every start logs to NAME.N.log: a restart keeps the earlier one's log
        self.procs = Procs(log_dir, env=self.env, numbered_logs=True)
        self.bport, self.sport = _free_udp(), _free_udp()
        self.cam = f"tcp://{LOCAL}:{free_port()}"
        self.proxy = Proxy((LOCAL, self.bport), seed=args.seed, record_ranges=lidar)
        self.bridge_starts: list[float] = []  # wall (monotonic) of each start of the bridge, for the observer
        self.watch = None
        self.simtwo = getattr(args, "simulator", "standin") == "simtwo"
        self.simtwo_keep: Path | None = None  # SimTwo: the folder of the running one (its log)
        self.sim_start_s = 180.0 if self.simtwo else 90.0  # wall s to the first frame (SimTwo: 5-30 s)

    def start_bridge(self):
        cmd = ["--field", self.args.field, "bridge", "--port", str(self.bport), "--sim-host", LOCAL]
        cmd += [] if self.lidar else ["--set", "lidar/enabled=false"]
        cmd += ["--camera", self.cam] if self.camera else ["--no-camera"]
        self.bridge_starts.append(time.monotonic())
        return self.procs.raf("bridge", *cmd)

    def observe(self, robot) -> Observer:
        """The observer over everything so far: the proxy's record against what the watcher received. The
        messages are taken first: a frame that goes out after the proxy's record is taken cannot then have a
        message among them (a /clock published from it was once reported as poisoned). The fates of the frames
        in that record (dropped, duplicated, ...) come with it as the observer's ``fates``, row for row with
        ``truth``."""
        published = self.watch.published()
        truth, fates, ranges = self.proxy.snapshot()
        return Observer(truth, published, Geometry.of(robot), self.bridge_starts, ranges, fates)

    def start_localize(self):
        return self.procs.raf("localize", "--field", self.args.field, "localize")

    def start_sim(self, extra=()):
        if self.simtwo:
            self.simtwo_keep = simtwo_side.keep_dir(self.procs)
            cam_port = int(self.cam.rsplit(":", 1)[1]) if self.camera else None
            return self.procs.start("sim", simtwo_side.command(self.args.field, self.sport, self.proxy.port,
                                                               cam_port, self.simtwo_keep))
        cmd = ["--field", self.args.field, "sim", "--port", str(self.sport), "--bridge", f"{LOCAL}:{self.proxy.port}",
               "--no-server", "--no-control", "--status-every", "5", "--seed", str(self.args.seed),
               f"--start-pose={self.start_pose}"]
        cmd += ["--camera-bind", self.cam] if self.camera else ["--no-camera"]
        cmd += ["--fast"] if self.fast else ["--realtime"]
        if self.lockstep:
            cmd += ["--lockstep", "--lockstep-timeout", "2.0"]
        return self.procs.raf("sim", *cmd, *extra)

    def up(self) -> "Rig":
        self.start_bridge()
        if self.localize:
            self.start_localize()
        self.master.use_in_this_process()
        self.watch = Watch()
        _wait(lambda: self.watch.cmd.subscriber_count() > 0, 60, "the bridge subscribing to cmd_vel", self.check)
        self.start_sim()
        _wait(lambda: len(self.watch.odom) > 5, self.sim_start_s, "odom from the bridge", self.check)
        if self.simtwo:
            self.place()
        return self

    def place(self) -> None:
        """SimTwo (no start pose option): the robot teleported to ``start_pose``."""
        simtwo_side.teleport(self.start_pose, node=self.watch.node)

    def kill_sim(self) -> None:
        """The simulator killed: ``raf sim`` with SIGKILL; SimTwo itself with SIGKILL (then its runner)."""
        if self.simtwo:
            simtwo_side.kill(self.procs, self.simtwo_keep)
        else:
            self.procs.kill("sim")

    def check(self) -> None:
        for name in ("bridge", "sim", "localize"):
            p = self.procs.get(name) if name in self.procs else None
            if p is not None and p.poll() is not None:
                raise RuntimeError(f"{name} exited with code {p.returncode}:\n{self.procs.log(name)[-2000:]}")

    def down(self) -> None:
        try:
            if self.watch is not None:
                self.watch.close()
        finally:
            self.procs.stop_all()
            self.proxy.close()
            self.master.stop()
            self._keep_ros_logs()
            self.master.cleanup()

    def _keep_ros_logs(self) -> None:
        """The private graph's ROS logs (roscore's master.log, rosout, this process's rospy log with the
        subscribers' publisher updates) kept beside the part's own logs as ``ros_log/``: what a restart that
        was never reconnected left (ROS 2 has none)."""
        src = self.master.home / "log"
        if src.is_dir():
            try:
                shutil.copytree(src, self.log_dir / "ros_log", symlinks=True, dirs_exist_ok=True)
            except OSError as e:
                print(f"faults: the ROS logs of {src} not kept: {e}", flush=True)


def circles(v=0.06, w=0.5):
    """Small loops (radius at most v / w) that stay in the open middle of the field."""
    return lambda t: (v * math.sin(0.4 * t), w)


# ------------------------------------------------------------------------------------------------ the parts

INBAND_RATE = 1000.0  # in-band datagrams a second (each is decoded and answered by the bridge)
TICKS_MIN_SECONDS = 3.0  # the impossible-ticks segment: one forged copy per real frame for this long at least
SEGMENT_PAUSE = 0.3  # wall s between two fuzz segments (what a kind did is counted up to the next one's start)


def _poison_figures(prefix: str, obs: Observer, log: Path, t0: float = -math.inf, t1: float = math.inf) -> dict:
    """The observer's verdict over [t0, t1): poisoned messages by topic (each one's reason in ``poisoned.json``
    beside the part's logs) and how many messages it checked."""
    bad = obs.poisoned_in(t0, t1)
    log.write_text(json.dumps([vars(x) for x in bad[:1000]], indent=1) + "\n")
    out = {f"{prefix}_messages_checked": sum(obs.counts().values()), f"{prefix}_scans_checked": obs.scans_checked,
           f"{prefix}_poisoned_messages": len(bad)}
    for topic in ("odom", "clock", "joints", "tf", "scan"):
        out[f"{prefix}_poisoned_{topic}"] = sum(1 for x in bad if x.topic == topic)
    if bad:
        out[f"{prefix}_poisoned_first"] = f"{bad[0].topic} stamp {bad[0].stamp_ms:.0f} ms: {bad[0].why}"
    out[f"{prefix}_poisoned_messages_target_met"] = not bad
    return out


def _save_bridge_diag(w: Watch, path: Path) -> None:
    """The bridge's own counters, kept beside the logs for reading; no figure comes from them."""
    with w.lock:
        path.write_text(json.dumps(w.diag, indent=1, default=str) + "\n")


def _inband_segment(rig: Rig, kind: str, datagrams: list, n: int, seconds: float) -> dict:
    """``n`` datagrams of one in-band kind from the simulator's own address (the proxy's socket), paced over
    ``seconds``: the sends that succeeded and the bridge socket's kernel drops meanwhile."""
    px = rig.proxy
    d0, inj0, t0 = udp_drops(rig.bport), px.counts["injected"], time.monotonic()
    i = 0
    while i < n:
        due = int(n * min(1.0, (time.monotonic() - t0) / seconds))
        while i < due:
            px.inject_queue.append(datagrams[i % len(datagrams)])
            i += 1
        rig.check()
        time.sleep(0.02)
    _wait(lambda: not px.inject_queue, 30, "the in-band fuzz to be sent")
    t1 = time.monotonic()
    time.sleep(0.05)
    d1 = udp_drops(rig.bport)
    return {"kind": kind, "where": "inband", "t0": t0, "t1": t1, "sent": px.counts["injected"] - inj0, "errors": 0,
            "drops": None if d0 is None or d1 is None else d1 - d0}


def _ticks_segment(rig: Rig, seconds: float) -> dict:
    """For ``seconds``, after every real frame a copy of the next one with encoder totals the wheels cannot
    reach (the proxy's ``forge_ticks_every``)."""
    px = rig.proxy
    d0, f0, t0 = udp_drops(rig.bport), px.counts.get("forged_ticks", 0), time.monotonic()
    px.forge_ticks_every = 1
    try:
        while time.monotonic() - t0 < seconds:
            rig.check()
            time.sleep(0.1)
    finally:
        px.forge_ticks_every = 0
    t1 = time.monotonic()
    time.sleep(0.05)
    d1 = udp_drops(rig.bport)
    return {"kind": "impossible_ticks", "where": "inband", "t0": t0, "t1": t1,
            "sent": px.counts.get("forged_ticks", 0) - f0, "errors": 0,
            "drops": None if d0 is None or d1 is None else d1 - d0}


def fuzz_plan(n_out: int, seconds: float) -> list[tuple[str, int, float]]:
    """The out-of-band kinds in turn: (kind, datagrams, wall seconds), shares by :data:`FOREIGN_KINDS`' weights,
    each kind's time in proportion to its datagrams."""
    total_w = sum(FOREIGN_KINDS.values())
    plan, left = [], n_out
    kinds = list(FOREIGN_KINDS)
    for i, k in enumerate(kinds):
        n = left if i == len(kinds) - 1 else n_out * FOREIGN_KINDS[k] // total_w
        left -= n
        plan.append((k, n, seconds * n / max(1, n_out)))
    return plan


def part_fuzz(args, log_dir: Path, robot) -> dict:
    import multiprocessing as mp
    import queue as queue_mod

    d = log_dir / "fuzz"
    d.mkdir(parents=True, exist_ok=True)
    rig = Rig(args, d, lidar=True).up()
    w, px = rig.watch, rig.proxy
    segments: list[dict] = []
    try:
        w.drive(circles())
        time.sleep(2.0)
        rng = random.Random(args.seed)
        with px.lock:
            template = px.template
        pool = fuzz_pool(template, rng)
        n_inband = int(args.fuzz_datagrams * args.fuzz_inband)
        n_out = args.fuzz_datagrams - n_inband
        ctx = mp.get_context("spawn")
        q = ctx.Queue()
        fz = ctx.Process(target=fuzzer, args=(rig.bport, {k: v for k, v in pool.items() if k != "inband"},
                                               fuzz_plan(n_out, args.fuzz_seconds), q), daemon=True)
        t_fuzz0 = time.monotonic()
        fz.start()
        deadline = t_fuzz0 + 4 * args.fuzz_seconds + 120
        rep = None
        while rep is None:
            try:
                rep = q.get(timeout=0.5)
            except queue_mod.Empty:
                rig.check()
                if time.monotonic() > deadline or not fz.is_alive() and q.empty():
                    raise RuntimeError("the fuzzer process did not report") from None
        fz.join(10)
        segments += [dict(s, where="foreign") for s in rep["segments"]]
        for kind in INBAND_KINDS:  # then the in-band kinds, one after the other
            time.sleep(SEGMENT_PAUSE)
            n = n_inband // len(INBAND_KINDS)
            segments.append(_inband_segment(rig, kind, pool["inband"][kind], n, max(1.0, n / INBAND_RATE)))
        time.sleep(SEGMENT_PAUSE)
        segments.append(_ticks_segment(rig, max(TICKS_MIN_SECONDS, args.fuzz_seconds / 10)))
        fuzz_wall = time.monotonic() - t_fuzz0
        time.sleep(1.0)
        w.stop_drive()
        time.sleep(1.5)  # the robot stops; the last frames arrive
        crashed = sum(1 for n in ("bridge", "sim") if rig.procs.get(n).poll() is not None)
        obs = rig.observe(robot)
        truth = obs.truth
        in_fuzz = [o for o in obs.pub.odom if t_fuzz0 <= o[0] <= t_fuzz0 + fuzz_wall]
        frames_in_fuzz = int(np.sum((truth[:, 0] >= t_fuzz0) & (truth[:, 0] <= t_fuzz0 + fuzz_wall)))
        errs = obs.odometry_errors()
        by_kind = obs.by_segment([(s["kind"], s["t0"], s["t1"]) for s in segments])
        (d / "segments.json").write_text(json.dumps(segments, indent=1) + "\n")
        _save_bridge_diag(w, d / "bridge_diagnostics.json")
    finally:
        rig.down()
    sent = sum(s["sent"] for s in segments)
    drops = [s["drops"] for s in segments]
    known = all(x is not None for x in drops)
    out = {"fuzz_datagrams_sent": sent, "fuzz_send_errors": sum(s["errors"] for s in segments),
           "fuzz_kernel_drops": sum(drops) if known else "not shown by /proc/net/udp",
           "fuzz_datagrams_reached_socket": sent - sum(drops) if known else sent,
           "fuzz_wall_s": round(fuzz_wall, 1), "fuzz_crashes": crashed}
    for s in segments:
        k = s["kind"]
        out[f"fuzz_{k}_sent"] = s["sent"]
        out[f"fuzz_{k}_reached"] = s["sent"] - (s["drops"] or 0)
        out[f"fuzz_{k}_poisoned"] = by_kind.get(k, 0)
        out[f"fuzz_{k}_poisoned_target_met"] = bool(by_kind.get(k, 0) == 0)
    out["fuzz_poisoned_outside_segments"] = by_kind.get("outside", 0)
    out.update(_poison_figures("fuzz", obs, d / "poisoned.json"))
    out.update({
        "fuzz_odom_messages": len(obs.pub.odom), "fuzz_frames_sent_by_sim": len(truth),
        "fuzz_odom_rate_during_fuzz_hz": round(len(in_fuzz) / fuzz_wall, 2),
        "fuzz_sim_frame_rate_during_fuzz_hz": round(frames_in_fuzz / fuzz_wall, 2),
        "fuzz_odometry_error_m": float(errs[:, 2].max()) if len(errs) else float("nan"),
        "fuzz_odometry_distance_m": float(np.sum(np.hypot(np.diff(truth[:, 5]), np.diff(truth[:, 6])))),
        "fuzz_crashes_target_met": bool(crashed == 0),
    })
    out["fuzz_odometry_error_target_met"] = bool(len(errs) and out["fuzz_odometry_error_m"] <= 0.01)
    return out


def part_loss(args, log_dir: Path, robot) -> dict:
    d = log_dir / "loss"
    d.mkdir(parents=True, exist_ok=True)
    rig = Rig(args, d, start_pose="-0.45,0.36,0", lidar=True).up()  # the corridor along the north machines
    w, px = rig.watch, rig.proxy
    try:
        t_loss0 = time.monotonic()
        px.set_faults(args.drop, args.dup, args.reorder)
        straight = min(4.5, args.loss_seconds / 2)  # 0.9 m at 0.2 m/s, then turning on the spot
        w.drive(lambda t: (0.2, 0.0) if t < straight else (0.0, 0.8 * math.sin(0.5 * (t - straight))))
        t0 = time.monotonic()
        while time.monotonic() - t0 < args.loss_seconds:
            rig.check()
            time.sleep(0.2)
        w.stop_drive()
        time.sleep(2.0)  # stopped: the totals stop changing, the last ones get through
        px.set_faults()
        t_loss1 = time.monotonic()
        time.sleep(1.0)
        rig.check()
        obs = rig.observe(robot)  # one record of the proxy's: the observer's truth and the frames' fates
        truth, fates = obs.truth, obs.fates
        np.save(d / "truth.npy", truth)
        _save_bridge_diag(w, d / "bridge_diagnostics.json")
    finally:
        rig.down()
    geo = Geometry.of(robot)
    rows = np.flatnonzero((truth[:, 0] >= t_loss0) & (truth[:, 0] < t_loss1))
    bound = chord_bound(truth, fates, geo, rows)
    errs = obs.odometry_errors(t_loss0, t_loss1)
    ticks = obs.joint_errors_ticks(t_loss0, t_loss1)
    # speed over the straight segment (from the simulator's own poses), after 1 s of acceleration
    tt = truth[:, 0] - t0
    seg = truth[(tt > 1.0) & (tt < straight - 0.2)]
    if len(seg) > 10:
        v = np.sum(np.hypot(np.diff(seg[:, 5]), np.diff(seg[:, 6]))) / ((seg[-1, 2] - seg[0, 2]) / 1000)
    else:
        v = float("nan")
    e_max = float(errs[:, 2].max()) if len(errs) else float("nan")
    h_max = float(errs[:, 3].max()) if len(errs) else float("nan")
    out = {"loss_drop": args.drop, "loss_dup": args.dup, "loss_reorder": args.reorder,
           "loss_proxy_dropped": px.counts["dropped"], "loss_proxy_duplicated": px.counts["duplicated"],
           "loss_proxy_reordered": px.counts["reordered"], "loss_frames_sent_by_sim": len(truth),
           "loss_frames_missing_runs": bound["runs"], "loss_frames_missing_longest_run": bound["longest"],
           "loss_chord_error_worst_m": bound["worst_m"], "loss_odometry_bound_m": bound["bound_m"],
           "loss_odom_messages_checked": len(errs), "loss_odometry_error_max_m": e_max,
           "loss_heading_error_max_rad": h_max,
           "loss_joint_messages_checked": len(ticks),
           "loss_ticks_off_max": int(ticks.max()) if len(ticks) else -1,
           "loss_speed_mps": float(v), "loss_speed_error_mps": float(abs(v - 0.2))}
    out.update(_poison_figures("loss", obs, d / "poisoned.json"))
    out["loss_odometry_error_max_target_met"] = bool(len(errs) > 10 and e_max <= bound["bound_m"])
    out["loss_heading_error_max_target_met"] = bool(len(errs) > 10 and h_max <= POSE_TOL_RAD)
    out["loss_ticks_off_max_target_met"] = bool(len(ticks) > 10 and ticks.max() == 0)
    out["loss_speed_error_target_met"] = bool(abs(v - 0.2) <= 0.01)
    return out


def part_restarts(args, log_dir: Path, robot) -> dict:
    d = log_dir / "restarts"
    d.mkdir(parents=True, exist_ok=True)
    camera = not args.no_camera_restart
    rig = Rig(args, d, camera=camera, lidar=True).up()
    w, px, out = rig.watch, rig.proxy, {}
    try:
        w.drive(circles())
        if camera:
            _wait(lambda: len(w.images) > 3, 60, "camera images", rig.check)
        time.sleep(2.0)
        # -- the simulator (and its camera publisher) killed and restarted
        rig.kill_sim()
        n_frames = len(px.frames)
        t_kill = time.monotonic()
        time.sleep(1.0)
        rig.start_sim()
        _wait(lambda: len(px.frames) > n_frames, rig.sim_start_s, "the restarted simulator's first frame",
              rig.check)
        with px.lock:
            t_first = px.frames[n_frames][0]
        _wait(lambda: any(x[0] > t_first for x in w.odom), 10, "odom after the restart", rig.check)
        if camera:
            _wait(lambda: any(x[0] > t_first for x in w.images), 10, "images after the restart", rig.check)
            out["restart_sim_image_back_s"] = min(x[0] for x in w.images if x[0] > t_first) - t_first
        out["restart_sim_process_start_to_first_frame_s"] = t_first - t_kill - 1.0
        time.sleep(2.5)
        if rig.simtwo:
            rig.place()  # the restarted SimTwo put the robot back at its scene's start
        # -- the bridge killed and restarted
        time.sleep(1.0)
        n_timeouts = len(simtwo_side.timeout_ages_s(rig.simtwo_keep))
        n_sim_log = len(rig.procs.log("sim"))
        t_bkill = time.monotonic()  # the signal: the bridge dies after it (a reply may still be on its way)
        rig.procs.kill("bridge")
        time.sleep(2.0)
        if rig.simtwo:  # control.pas's line, in ms, once per timeout; the first after the kill
            ages = simtwo_side.timeout_ages_s(rig.simtwo_keep)[n_timeouts:][:1]
        else:
            ages = [float(a) for a in re.findall(r"no valid command for ([0-9.]+) s", rig.procs.log("sim")[n_sim_log:])]
        rig.start_bridge()
        t_bstart = rig.bridge_starts[-1]
        n_rep = len(px.replies)
        _wait(lambda: len(px.replies) > n_rep, 90, "the restarted bridge's first reply", rig.check)
        with px.lock:
            t_rep = px.replies[n_rep][0]
        _wait(lambda: any(o[0] > t_rep for o in w.odom), 15, "odom from the restarted bridge", rig.check)
        time.sleep(1.0)
        obs = rig.observe(robot)
        with px.lock:
            replies = list(px.replies)
        np.save(d / "truth.npy", obs.truth)
        (d / "events.json").write_text(json.dumps({"bridge_killed": t_bkill, "bridge_started": t_bstart,
                                                   "replies": replies[-200:]}) + "\n")
        _save_bridge_diag(w, d / "bridge_diagnostics.json")
        # -- roscore killed and restarted on the same port
        out.update(_roscore_restart(rig))
    finally:
        rig.down()
    truth = obs.truth
    new_run = int(obs.epoch[n_frames]) if n_frames < len(truth) else -1

    def back(topic, after, epoch=None):
        t = obs.first_valid(topic, after, epoch)
        return float("inf") if t is None else t - after

    out["restart_sim_odom_back_s"] = back("odom", t_first, new_run)
    out["restart_sim_clock_back_s"] = back("clock", t_first, new_run)
    out["restart_sim_odometry_resets"] = obs.resets()
    out.update(at_rest(truth, replies, t_bkill, t_bstart, track=robot.odometry_track))
    # the simulator's own record (informational): the age of its last command when its timeout fired
    out["restart_bridge_timeout_age_logged_s"] = float(ages[0]) if ages else float("nan")
    out["restart_bridge_resume_s"] = back("odom", t_rep)
    out["restart_bridge_process_start_to_first_reply_s"] = t_rep - t_bstart
    # how late this node's subscriptions joined the restarted bridge (informational; the observer recovers
    # the bridge's baseline across them): frames it published before the first message seen, and their span
    n_unseen, s_unseen = obs.unseen_at_join(len(obs.starts) - 1)
    out["restart_bridge_frames_unseen_at_join"] = n_unseen
    out["restart_bridge_unseen_at_join_s"] = round(s_unseen, 3)
    out.update(_poison_figures("restart", obs, d / "poisoned.json"))
    out.update({k: bool(v) for k, v in {
        "restart_sim_odom_back_target_met": out["restart_sim_odom_back_s"] <= 1.0,
        "restart_sim_clock_back_target_met": out["restart_sim_clock_back_s"] <= 1.0,
        "restart_sim_odometry_resets_target_met": out["restart_sim_odometry_resets"] == 1,
        "restart_bridge_stop_target_met": out["restart_bridge_stop_s"] <= STOP_S + 1e-6,
        "restart_bridge_at_rest_target_met": out["restart_bridge_at_rest_s"] <= 0.54 + 1e-6,
        "restart_bridge_at_rest_after_death_target_met": out["restart_bridge_at_rest_after_death_s"] <= 0.6,
        "restart_bridge_resume_target_met": out["restart_bridge_resume_s"] <= 1.0,
    }.items()})
    if camera:
        out["restart_sim_image_back_target_met"] = out["restart_sim_image_back_s"] <= 1.0
    return out


def at_rest(truth: np.ndarray, replies: list, t_kill: float, until: float, applied_after: int = 1,
            still_m: float = 2e-4, still_rad: float = 2e-3, track: float = 0.2, window: int = 5) -> dict:
    """From the simulator's frames (ground truth) after the bridge was killed at ``t_kill`` (wall: the signal)
    and before it was started again at ``until``, in simulation seconds after the last command the simulator
    applied (the dead bridge's last reply, which may reach the proxy just after the signal; applied from the
    cycle after the frame it answered: ``applied_after``; control.pas reads a reply in its next cycle, and
    raf sim's logged age puts it there too):

    * ``restart_bridge_stop_s``: the start of the first cycle whose motion (ground-truth path plus half the
      track times the turn) drops below 70 % of the steady motion before (the timeout's V = W = 0);
    * ``restart_bridge_at_rest_s``: the robot at rest for good: from this frame on no wheel turns more than one
      encoder tick in a cycle, the robot's mean speed over every later ``window`` cycles (0.2 s) stays under
      ``still_m`` and ``still_rad`` a cycle (5 mm/s, 0.05 rad/s), and no single cycle moves it more than twice
      that. A speed is judged over 0.2 s, not a cycle, because SimTwo's resting robot jitters: its ground truth
      moves by up to 0.22 mm and 2.2 mrad in a cycle for seconds after a stop, back and forth (a per-cycle
      threshold at 5 mm/s and 0.05 rad/s, the first criterion, put the moment of rest wherever a jitter
      sample happened to exceed it); ``restart_bridge_at_rest_after_death_s``: the same moment in wall
      seconds after the bridge's death (the arrival of that frame, which carries the pose at its Tms)."""
    nan = float("nan")
    none = {"restart_bridge_at_rest_s": nan, "restart_bridge_at_rest_after_death_s": nan,
            "restart_bridge_stop_s": nan}
    reps = [r for r in replies if r[0] < until]  # the dead bridge's: its last may arrive just after the kill
    if not reps or not len(truth):
        return none
    k = int(np.sum(truth[:, 0] <= reps[-1][0])) - 1 + applied_after
    end = int(np.sum(truth[:, 0] < until))
    win = truth[k:end]
    if k < 0 or len(win) < window + 2:
        return none
    t_cmd = win[0, 2] / 1000
    step = np.hypot(np.diff(win[:, 5]), np.diff(win[:, 6]))
    turn = np.abs(np.remainder(np.diff(win[:, 7]) + math.pi, 2 * math.pi) - math.pi)
    ticks = np.maximum(np.abs(np.diff(win[:, 3])), np.abs(np.diff(win[:, 4])))
    # the mean speed over the window starting at each frame: net displacement and turn over ``window`` cycles
    n = len(win) - window
    net_m = np.hypot(win[window:, 5] - win[:n, 5], win[window:, 6] - win[:n, 6]) / window
    net_rad = np.abs(np.remainder(win[window:, 7] - win[:n, 7] + math.pi, 2 * math.pi) - math.pi) / window
    still_cycle = (ticks <= 1) & (step <= 2 * still_m) & (turn <= 2 * still_rad)
    still_mean = (net_m <= still_m) & (net_rad <= still_rad)
    j = len(win) - 1
    while j > 0 and still_cycle[j - 1] and (j - 1 >= n or still_mean[j - 1]):
        j -= 1
    if j >= n:  # not at rest over a whole window before the end
        return none
    motion = step + track / 2 * turn
    steady = float(np.median(motion[: max(1, int(np.sum(win[:, 2] / 1000 - t_cmd < 0.4)))]))
    stop = next((float(win[i, 2] / 1000 - t_cmd) for i in range(len(motion)) if motion[i] < 0.7 * steady), nan)
    return {"restart_bridge_at_rest_s": round(float(win[j, 2] / 1000 - t_cmd), 3),
            "restart_bridge_at_rest_after_death_s": round(float(win[j, 0] - t_kill), 3),
            "restart_bridge_stop_s": round(stop, 3)}


def _roscore_restart(rig: Rig) -> dict:
    from ..ros.master import stop_process

    names = [n for n in ("bridge", "localize") if n in rig.procs]
    stop_process(rig.master.proc, signal.SIGINT)
    time.sleep(1.0)
    rig.master.start()
    t0 = time.monotonic()
    exited, clear = {}, {}
    while time.monotonic() - t0 < 15 and len(exited) < len(names):
        for n in names:
            p = rig.procs.get(n)
            if n not in exited and p.poll() is not None:
                exited[n] = p.returncode
        time.sleep(0.2)
    for n in names:
        log = rig.procs.log(n)
        clear[n] = "the ROS master restarted" in log
    ok = all(n in exited and clear[n] for n in names)
    return {"restart_roscore_exit_codes": json.dumps(exited), "restart_roscore_exit_s": round(time.monotonic() - t0, 1),
            "restart_roscore_nodes_clear": ok, "restart_roscore_nodes_clear_target_met": ok}


PARTS = {"fuzz": part_fuzz, "loss": part_loss, "restarts": part_restarts, "soak": part_soak}


def _part_child(name: str, opts: dict, log_dir: str, q) -> None:
    """A part in a fresh interpreter: rospy binds a process to one master for good, and each part (and the
    roscore restart) has its own."""
    import argparse

    def on_term(*_):
        raise SystemExit("terminated")

    signal.signal(signal.SIGTERM, on_term)
    from ..robot import load_robot

    try:
        q.put({"ok": PARTS[name](argparse.Namespace(**opts), Path(log_dir), load_robot())})
    except BaseException as e:  # noqa: BLE001 - reported to the parent, which decides
        q.put({"error": f"{type(e).__name__}: {e}"})
        raise SystemExit(1) from None


def part_timeout(name: str, args) -> float:
    """Wall seconds a part may take before it is stopped (generous: a loaded machine is slow)."""
    sim_s = args.soak_sim_seconds if args.soak_sim_seconds is not None else args.soak_minutes * 60
    simtwo_starts = {"restarts": 2}.get(name, 1) if getattr(args, "simulator", "standin") == "simtwo" else 0
    return 240 + 150 * simtwo_starts + {"fuzz": 3 * args.fuzz_seconds + args.fuzz_datagrams / 2000,
                                        "loss": 3 * args.loss_seconds, "restarts": 120, "soak": 2 * sim_s}[name]


def run_part(name: str, args, log_dir: Path) -> dict:
    """Run one part in a child process; RuntimeError with the reason when it fails or overruns."""
    import multiprocessing as mp
    import queue as queue_mod

    opts = {k: v for k, v in vars(args).items() if isinstance(v, (int, float, str, bool, type(None)))}
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_part_child, args=(name, opts, str(log_dir), q), name=f"raf-faults-{name}")
    p.start()
    limit = part_timeout(name, args)
    try:
        msg = q.get(timeout=limit)
    except queue_mod.Empty:
        msg = {"error": f"no result within {limit:.0f} s"}
    finally:
        p.join(30)
        if p.is_alive():
            p.terminate()  # SIGTERM: the part's clean-up (its processes, its roscore) still runs
            p.join(30)
        if p.is_alive():
            p.kill()
            p.join(5)
    if "error" in msg:
        raise RuntimeError(f"{name}: {msg['error']} (the part's logs, its ROS logs in ros_log/: {log_dir})")
    return msg["ok"]


def table(res: dict) -> str:
    rows = ["| figure | value | target | met |", "|---|---|---|---|"]
    for k, v in res.items():
        if k.endswith("_target_met") or k == "notes":
            continue
        met = res.get(_met_key(k, res))
        target = TARGETS.get(k, "")
        val = f"{v:.4g}" if isinstance(v, float) else str(v)
        rows.append(f"| {k} | {val} | {target} | {'' if met is None else ('yes' if met else '**NO**')} |")
    return "\n".join(rows)


def _met_key(k: str, res: dict) -> str:
    for cand in (f"{k}_target_met", f"{k.rsplit('_', 1)[0]}_target_met"):
        if cand in res:
            return cand
    return ""


def run(args, out_dir: Path | None) -> dict:
    from ..errors import ConfigError
    from ..robot import load_robot

    simtwo = getattr(args, "simulator", "standin") == "simtwo"
    parts_arg = args.parts or (",".join(simtwo_side.PARTS) if simtwo else ",".join(PARTS))
    parts = [p.strip() for p in parts_arg.split(",") if p.strip()]
    for p in parts:
        if p not in PARTS:
            raise ConfigError(f"--parts: unknown part {p!r}; choose from {', '.join(PARTS)}")
    if simtwo:
        from ..simtwo_linux.scene import field_for_simtwo

        simtwo_side.check_parts(parts)
        args.field = field_for_simtwo(args.field)  # SimTwo's scene is not the rules' field
    if args.fuzz_datagrams < 0 or not 0 <= args.fuzz_inband <= 1:
        raise ConfigError("--fuzz-datagrams must be >= 0 and --fuzz-inband within 0..1")
    if not (0 <= args.drop < 1 and 0 <= args.dup < 1 and 0 <= args.reorder < 1
            and args.drop + args.dup + args.reorder < 1):
        raise ConfigError("--drop, --dup and --reorder are shares within 0..1 (their sum below 1)")
    load_robot()  # a broken robot spec fails here, before any process starts
    log_dir = (out_dir / "logs") if out_dir is not None else Path(tempfile.mkdtemp(prefix="raf-exp-faults-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    res: dict = {}
    notes = []
    for p in parts:
        t0 = time.monotonic()
        print(f"faults: {p} ...", flush=True)
        try:
            res.update(run_part(p, args, log_dir))
        except RuntimeError as e:
            notes.append(f"{p}: {e}")
            res[f"{p}_completed_target_met"] = False
            print(f"faults: {p} failed: {e} (logs in {log_dir})", file=sys.stderr, flush=True)
        # the part's whole wall time (setup included); not {p}_wall_s, which a part may report itself (the fuzz's
        # own phase: fuzz_wall_s)
        res[f"{p}_part_wall_s"] = round(time.monotonic() - t0, 1)
        if p in OBSERVED_MODES:  # which simulator and mode produced the part's figures
            res[f"{p}_mode"] = OBSERVED_MODES[p]["simtwo" if simtwo else "standin"]
    if simtwo:
        res = simtwo_side.result(res)
    print(table(res))
    if out_dir is not None:
        (out_dir / "faults_table.md").write_text(table(res) + "\n")
    res["notes"] = "; ".join(notes) + (f"; logs in {log_dir}" if notes else "")
    return res
