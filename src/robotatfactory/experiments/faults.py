"""``raf experiment faults``: the fault campaign of issue 10, on the real ``raf sim``, bridge and localization.

Everything runs on loopback (127.0.0.1) with a private roscore. Between the simulator and the bridge sits a
UDP proxy in this process (:class:`._faults_net.Proxy`): it records every SensorFrame the simulator sent (the
loss-free, fuzz-free truth) and, per part, drops, duplicates, reorders or injects datagrams. The bridge's stream
is bound to the proxy's address (its only legitimate sender).

Parts (``--parts``, all by default):

* **fuzz**: while the robot drives, ``--fuzz-datagrams`` datagrams (default 1,000,000) go to the bridge's port:
  from other source addresses (a fuzzer process: random bytes, mutated copies of a real SensorFrame, frames
  with forged far-future Seq/Tms, oversized, non-ASCII, and a second sender streaming valid frames), and a
  share (``--fuzz-inband``) from the simulator's own source address through the proxy (far-future Seq, far-
  future Tms, clock going back, lone restart-like frames, impossible encoder totals, undecodable mutations,
  oversized and non-ASCII datagrams). Figures: the bridge still runs (0 crashes); odom and /clock messages
  whose stamp is not the Tms of a frame the simulator sent (0: forged and foreign frames never reach them);
  the bridge's final odometry against the same odometry integrated over every frame the simulator sent
  (the fuzz-free result), target 1 cm.
* **loss**: the proxy drops ``--drop`` (20 %), duplicates ``--dup`` (5 %) and reorders ``--reorder`` (5 %) of
  the SensorFrames and of the Commands. Figures: encoder ticks the bridge lost (its wheel angles at the end
  against the simulator's cumulative totals, which are what a loss-free run counts), target 0; the robot
  still follows cmd_vel (mean speed over a straight segment against the command, target 1 cm/s).
* **restarts**: the simulator (with its camera publisher) killed and restarted (odom, /clock and images back
  within 1 s of its first frame; odometry reset once); the bridge killed and restarted (the simulator's
  command timeout stops the robot within 0.5 s of its last command; the new bridge's odom within 1 s of its
  first reply); roscore killed and restarted on the same port (every node exits with a clear message, or
  keeps going: reported).
* **soak** (:mod:`._faults_soak`, issue 22): ``--soak-minutes`` (default 60) of the whole stack as SimTwo runs
  it: ``raf sim`` free-running in real time (camera, LIDAR, factory server), the bridge, the localization and
  ``raf agent`` playing rounds one after another; memory, CPU, message rates and the loop latency in control
  cycles at the start and at the end; memory growth under 5 %, no process died.

Each figure comes with its target; ``raf experiment`` reports the ``*_target_met`` keys (it exits non-zero
when one is missed, see commands/experiment.py).

Simulator. ``--simulator standin`` (the default) runs ``raf sim``; ``--simulator simtwo`` runs the real SimTwo
(``raf simtwo run``, field ``simtwo2022``) behind the same proxy: fuzz, loss and restarts, with the keys
prefixed ``real_simtwo_``. What SimTwo cannot do (no ``--fast``, no lockstep: no soak; no start pose option:
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
import signal
import socket
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from . import _faults_simtwo as simtwo_side
from ._faults_net import LOCAL, Proxy, fuzz_pool, fuzzer
from ._faults_soak import TARGETS as SOAK_TARGETS
from ._faults_soak import part_soak
from ._faults_watch import Watch

NAME = "faults"
HELP = ("fault campaign (issue 10): fuzz, loss, restarts and soak on the real raf sim, bridge and localization "
        "(--simulator simtwo: fuzz, loss and restarts on the real SimTwo)")
TARGETS = {
    "fuzz_crashes": "0",
    "fuzz_odom_from_forged_or_foreign": "0",
    "fuzz_clock_from_forged_or_foreign": "0",
    "fuzz_odometry_error_m": "<= 0.01 m against the fuzz-free odometry",
    "loss_ticks_lost": "0 against the simulator's totals (the loss-free count)",
    "loss_speed_error_mps": "<= 0.01 m/s (the robot follows cmd_vel)",
    "restart_sim_odom_back_s": "<= 1 s",
    "restart_sim_clock_back_s": "<= 1 s",
    "restart_sim_image_back_s": "<= 1 s",
    "restart_sim_odometry_resets": "1",
    "restart_bridge_stop_s": "<= 0.54 s (simulation) from the last command to V = W = 0 (the simulator's log): "
                             "the 0.5 s command timeout plus one 40 ms cycle, as control.pas checks it (issue 22)",
    "restart_bridge_resume_s": "<= 1 s",
    "restart_roscore_nodes_clear": "every node exits with a clear message (or reconnects)",
}
TARGETS.update({f"{simtwo_side.MODE}_{k}": v for k, v in list(TARGETS.items())
                if k not in simtwo_side.TARGETS_NOT_APPLICABLE})
TARGETS.update(SOAK_TARGETS)  # the stand-in only (the soak resets rounds through raf sim's control channel)
EXIT_STATUS_FROM_TARGETS = True  # raf experiment faults exits 1 when a target is missed
PERIOD = 0.04


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


def reference_odometry(truth: np.ndarray, robot, start_index: int = 0) -> tuple[float, float, float]:
    """The bridge's odometry over every frame the simulator sent (in Seq order, from zero): the fuzz-free and
    loss-free result."""
    from ..localization.odometry import DiffDriveOdometry

    odo = DiffDriveOdometry(wheel_radius=robot.wheel_radius, track=robot.odometry_track,
                            ticks_per_rev=robot.ticks_per_rev)
    odo.reset(baseline=(0, 0), t=0.0)
    rows = truth[start_index:]
    rows = rows[np.argsort(rows[:, 1], kind="stable")]
    s = None
    for r in rows:
        s = odo.update(int(r[3]), int(r[4]), r[2] / 1000.0)
    return (s.x, s.y, s.theta) if s is not None else (0.0, 0.0, 0.0)


# ------------------------------------------------------------------------------------------------ the rig

class Rig:
    """roscore + bridge (+ localization) + proxy + raf sim (or SimTwo), started and restarted on demand."""

    def __init__(self, args, log_dir: Path, camera: bool = False, localize: bool = False, fast: bool = False,
                 lockstep: bool = False, start_pose: str = "0.0,0.0,1.5708"):
        from ..ros.master import PrivateMaster, free_port
        from ..ros.processes import Procs

        self.args, self.camera, self.localize, self.fast, self.lockstep = args, camera, localize, fast, lockstep
        self.start_pose = start_pose  # the open middle of the field (rules2026); the loss part drives a corridor
        self.master = PrivateMaster().start()
        self.env = self.master.env(MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
        # every start logs to NAME.N.log: a restart keeps the earlier one's log
        self.procs = Procs(log_dir, env=self.env, numbered_logs=True)
        self.bport, self.sport = _free_udp(), _free_udp()
        self.cam = f"tcp://{LOCAL}:{free_port()}"
        self.proxy = Proxy((LOCAL, self.bport), seed=args.seed)
        self.watch = None
        self.simtwo = getattr(args, "simulator", "standin") == "simtwo"
        self.simtwo_keep: Path | None = None  # SimTwo: the folder of the running one (its log)
        self.sim_start_s = 180.0 if self.simtwo else 90.0  # wall s to the first frame (SimTwo: 5-30 s)

    def start_bridge(self):
        cmd = ["--field", self.args.field, "bridge", "--port", str(self.bport), "--sim-host", LOCAL,
               "--set", "lidar/enabled=false"]
        cmd += ["--camera", self.cam] if self.camera else ["--no-camera"]
        return self.procs.raf("bridge", *cmd)

    def start_localize(self):
        return self.procs.raf("localize", "--field", self.args.field, "localize")

    def start_sim(self, extra=()):
        if self.simtwo:
            self.simtwo_keep = simtwo_side.keep_dir(self.procs)
            cam_port = int(self.cam.rsplit(":", 1)[1]) if self.camera else None
            return self.procs.start("sim", simtwo_side.command(self.args.field, self.sport, self.proxy.port,
                                                               cam_port, self.simtwo_keep))
        cmd = ["--field", self.args.field, "sim", "--port", str(self.sport), "--bridge", f"{LOCAL}:{self.proxy.port}",
               "--no-server", "--status-every", "5", "--seed", str(self.args.seed), f"--start-pose={self.start_pose}"]
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
            self.master.cleanup()


def circles(v=0.06, w=0.5):
    """Small loops (radius at most v / w) that stay in the open middle of the field."""
    return lambda t: (v * math.sin(0.4 * t), w)


# ------------------------------------------------------------------------------------------------ the parts

def part_fuzz(args, log_dir: Path, robot) -> dict:
    import multiprocessing as mp

    (log_dir / "fuzz").mkdir(parents=True, exist_ok=True)
    rig = Rig(args, log_dir / "fuzz").up()
    w, px = rig.watch, rig.proxy
    out = {}
    try:
        w.drive(circles())
        time.sleep(2.0)
        rng = random.Random(args.seed)
        with px.lock:
            template = px.template
        pool = fuzz_pool(template, rng)
        px.forge_ticks_every = 2
        n_inband = int(args.fuzz_datagrams * args.fuzz_inband)
        n_out = args.fuzz_datagrams - n_inband
        ctx = mp.get_context("spawn")
        q = ctx.Queue()
        fz = ctx.Process(target=fuzzer, args=(rig.bport, {k: v for k, v in pool.items() if k != "inband"}, n_out,
                                               args.fuzz_seconds, q), daemon=True)
        t_fuzz0 = time.monotonic()
        fz.start()
        inband = pool["inband"]
        i = 0
        while i < n_inband:  # paced like the fuzzer, through the proxy's socket (the bound source)
            due = int(n_inband * min(1.0, (time.monotonic() - t_fuzz0) / args.fuzz_seconds))
            while i < due:
                px.inject_queue.append(inband[i % len(inband)])
                i += 1
            rig.check()
            time.sleep(0.02)
        sent = q.get(timeout=args.fuzz_seconds * 4 + 120)
        px.forge_ticks_every = 0
        fz.join(10)
        _wait(lambda: not px.inject_queue, 30, "the in-band fuzz to be sent")
        fuzz_wall = time.monotonic() - t_fuzz0
        time.sleep(1.0)
        w.stop_drive()
        time.sleep(1.5)  # the robot stops; the last frames arrive
        rig.check()
        crashed = sum(1 for n in ("bridge", "sim") if rig.procs.get(n).poll() is not None)
        truth = px.truth()
        real_ms = set(truth[:, 2].astype(int).tolist())
        with w.lock:
            odom, clock = list(w.odom), list(w.clock)
        bad_odom = sum(1 for o in odom if o[1] not in real_ms)
        bad_clock = sum(1 for c in clock if c[1] not in real_ms)
        ref = reference_odometry(truth, robot)
        last = odom[-1]
        err = math.hypot(last[2] - ref[0], last[3] - ref[1])
        # odom published during the fuzz against the frames the simulator sent then
        in_fuzz = [o for o in odom if t_fuzz0 <= o[0] <= t_fuzz0 + fuzz_wall]
        frames_in_fuzz = int(np.sum((truth[:, 0] >= t_fuzz0) & (truth[:, 0] <= t_fuzz0 + fuzz_wall)))
        time.sleep(1.2)
        d = w.stream_diag()
        out = {
            "fuzz_datagrams_sent": int(sent["total"]) + px.counts["injected"] + px.counts.get("forged_ticks", 0),
            "fuzz_inband_sent": px.counts["injected"], "fuzz_impossible_ticks_sent": px.counts.get("forged_ticks", 0),
            "fuzz_wall_s": round(fuzz_wall, 1),
            "fuzz_second_sender_frames": sent["second_sender"], "fuzz_send_errors": sent["errors"],
            "fuzz_crashes": crashed,
            "fuzz_odom_messages": len(odom), "fuzz_frames_sent_by_sim": len(truth),
            "fuzz_odom_rate_during_fuzz_hz": round(len(in_fuzz) / fuzz_wall, 2),
            "fuzz_sim_frame_rate_during_fuzz_hz": round(frames_in_fuzz / fuzz_wall, 2),
            "fuzz_odom_from_forged_or_foreign": bad_odom, "fuzz_clock_from_forged_or_foreign": bad_clock,
            "fuzz_odometry_error_m": err,
            "fuzz_odometry_distance_m": float(np.sum(np.hypot(np.diff(truth[:, 5]), np.diff(truth[:, 6])))),
        }
        for k in ("rejected_foreign_source", "rejected_malformed", "rejected_oversized", "rejected_foreign_protocol",
                  "held", "implausible", "restarts", "stale", "duplicates", "lost", "bound_source",
                  "source_takeovers"):
            if k in d:
                out[f"fuzz_bridge_{k}"] = d[k] if k == "bound_source" else int(float(d[k]))
        out.update({
            "fuzz_crashes_target_met": crashed == 0,
            "fuzz_odom_from_forged_or_foreign_target_met": bad_odom == 0,
            "fuzz_clock_from_forged_or_foreign_target_met": bad_clock == 0,
            "fuzz_odometry_error_target_met": err <= 0.01,
            "fuzz_odometry_reset_target_met": int(float(d.get("restarts", -1))) == 0,
        })
    finally:
        rig.down()
    return out


def part_loss(args, log_dir: Path, robot) -> dict:
    (log_dir / "loss").mkdir(parents=True, exist_ok=True)
    rig = Rig(args, log_dir / "loss", start_pose="-0.45,0.36,0").up()  # the corridor along the north machines
    w, px = rig.watch, rig.proxy
    try:
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
        time.sleep(1.0)
        rig.check()
        truth = px.truth()
        np.save(log_dir / "loss" / "truth.npy", truth)
        with w.lock:
            joints = list(w.joints)
        tpr = robot.ticks_per_rev
        jl, jr = joints[-1][2], joints[-1][3]
        bl, br = round(jl * tpr / (2 * math.pi)), round(jr * tpr / (2 * math.pi))
        sl, sr = int(truth[-1, 3]), int(truth[-1, 4])
        lost = abs(bl - sl) + abs(br - sr)
        # speed over the straight segment (from the simulator's own poses), after 1.5 s of acceleration
        tt = truth[:, 0] - t0
        seg = truth[(tt > 1.0) & (tt < straight - 0.2)]
        if len(seg) > 10:
            dist = np.sum(np.hypot(np.diff(seg[:, 5]), np.diff(seg[:, 6])))
            v = dist / ((seg[-1, 2] - seg[0, 2]) / 1000)
        else:
            v = float("nan")
        ref = reference_odometry(truth, robot)
        with w.lock:
            last = w.odom[-1]
        time.sleep(1.2)
        d = w.stream_diag()
        out = {"loss_drop": args.drop, "loss_dup": args.dup, "loss_reorder": args.reorder,
               "loss_proxy_dropped": px.counts["dropped"], "loss_proxy_duplicated": px.counts["duplicated"],
               "loss_proxy_reordered": px.counts["reordered"], "loss_frames_sent_by_sim": len(truth),
               "loss_bridge_ticks": f"{bl},{br}", "loss_sim_ticks": f"{sl},{sr}", "loss_ticks_lost": int(lost),
               "loss_speed_mps": float(v), "loss_speed_error_mps": float(abs(v - 0.2)),
               "loss_odometry_vs_lossfree_m": math.hypot(last[2] - ref[0], last[3] - ref[1])}
        for k in ("lost", "duplicates", "stale", "held", "restarts", "accepted"):
            if k in d:
                out[f"loss_bridge_{k}"] = int(float(d[k]))
        out["loss_ticks_lost_target_met"] = lost == 0
        out["loss_speed_error_target_met"] = bool(abs(v - 0.2) <= 0.01)
    finally:
        rig.down()
    return out


def part_restarts(args, log_dir: Path, robot) -> dict:
    (log_dir / "restarts").mkdir(parents=True, exist_ok=True)
    camera = not args.no_camera_restart
    rig = Rig(args, log_dir / "restarts", camera=camera).up()
    w, px, out = rig.watch, rig.proxy, {}
    try:
        w.drive(circles())
        if camera:
            _wait(lambda: len(w.images) > 3, 60, "camera images", rig.check)
        time.sleep(2.0)
        d0 = _wait_diag(w)
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

        def back(lst, what):
            _wait(lambda: any(x[0] > t_first for x in lst), 10, what, rig.check)
            return min(x[0] for x in lst if x[0] > t_first) - t_first

        out["restart_sim_odom_back_s"] = back(w.odom, "odom after the restart")
        out["restart_sim_clock_back_s"] = back(w.clock, "/clock after the restart")
        if camera:
            out["restart_sim_image_back_s"] = back(w.images, "images after the restart")
        out["restart_sim_process_start_to_first_frame_s"] = t_first - t_kill - 1.0
        time.sleep(2.5)
        d1 = _wait_diag(w, after=time.monotonic())
        out["restart_sim_odometry_resets"] = int(float(d1.get("restarts", -1))) - int(float(d0.get("restarts", 0)))
        with w.lock:
            first_after = [o for o in w.odom if o[0] > t_first][:1]
        out["restart_sim_first_odom_stamp_s"] = first_after[0][1] / 1000 if first_after else -1.0
        if rig.simtwo:
            rig.place()  # the restarted SimTwo put the robot back at its scene's start
        # -- the bridge killed and restarted
        time.sleep(1.0)
        n_rep = len(px.replies)
        n_timeouts = len(simtwo_side.timeout_ages_s(rig.simtwo_keep))
        rig.procs.kill("bridge")
        t_kill = time.monotonic()
        with px.lock:
            last_rep = px.replies[-1] if px.replies else None
        time.sleep(2.0)
        truth = px.truth()
        # SimTwo's script applies a reply in the cycle after the frame it answers
        out.update(_stop_after_last_command(truth, px, t_kill, applied_after=1 if rig.simtwo else 0))
        import re

        if rig.simtwo:  # control.pas's line, in ms, once per timeout; the first after the kill
            ages = simtwo_side.timeout_ages_s(rig.simtwo_keep)[n_timeouts:][:1]
        else:
            ages = [float(a) for a in re.findall(r"no valid command for ([0-9.]+) s", rig.procs.log("sim"))]
        # the simulator's own record: the age of its last command when its timeout replaced it by V = W = 0
        out["restart_bridge_stop_s"] = float(ages[-1]) if ages else float("nan")
        rig.start_bridge()
        n_rep = len(px.replies)
        _wait(lambda: len(px.replies) > n_rep, 90, "the restarted bridge's first reply", rig.check)
        with px.lock:
            t_rep = px.replies[n_rep][0]
        _wait(lambda: any(o[0] > t_rep for o in w.odom), 15, "odom from the restarted bridge", rig.check)
        out["restart_bridge_resume_s"] = min(o[0] for o in w.odom if o[0] > t_rep) - t_rep
        out["restart_bridge_process_start_to_first_reply_s"] = t_rep - t_kill - 2.0
        del last_rep
        # -- roscore killed and restarted on the same port
        out.update(_roscore_restart(rig))
        out.update({
            "restart_sim_odom_back_target_met": out["restart_sim_odom_back_s"] <= 1.0,
            "restart_sim_clock_back_target_met": out["restart_sim_clock_back_s"] <= 1.0,
            "restart_sim_odometry_resets_target_met": out["restart_sim_odometry_resets"] == 1,
            "restart_bridge_stop_target_met": out["restart_bridge_stop_s"] <= 0.54 + 1e-6,
            "restart_bridge_resume_target_met": out["restart_bridge_resume_s"] <= 1.0,
        })
        if camera:
            out["restart_sim_image_back_target_met"] = out["restart_sim_image_back_s"] <= 1.0
    finally:
        rig.down()
    return out


def _wait_diag(w: Watch, after: float | None = None, timeout: float = 10.0) -> dict:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        d = w.stream_diag()
        if d and (after is None or time.monotonic() - after > 1.2):
            return d
        time.sleep(0.1)
    return w.stream_diag()


def _stop_after_last_command(truth: np.ndarray, px: Proxy, t_kill: float, applied_after: int = 0) -> dict:
    """From the frames the simulator sent after the bridge died: when (simulation time, after the last command
    it got) its command timeout stopped the wheels (the first cycle whose encoder counts do not move), and
    when the robot was at rest. ``applied_after``: frames after the last reply's arrival the simulator applies
    it from (``raf sim``: 0, from the last frame before it; SimTwo: 1, from the next frame's cycle)."""
    with px.lock:
        reps = [r for r in px.replies if r[0] <= t_kill]
    if not reps:
        return {"restart_bridge_stop_s": float("nan")}
    t_last_rep = reps[-1][0]
    n_before = int(np.sum(truth[:, 0] <= t_last_rep)) + applied_after
    before, after = truth[:n_before], truth[n_before:]
    t_cmd = before[-1, 2] / 1000  # the simulator applied the last command from this frame's time on
    rest_t = float("nan")
    prev = before[-1]
    for r in after:
        dl, dr = r[3] - prev[3], r[4] - prev[4]
        moving = math.hypot(r[5] - prev[5], r[6] - prev[6]) > 2e-4
        if math.isnan(rest_t) and dl == 0 and dr == 0 and not moving:
            rest_t = r[2] / 1000 - t_cmd
        prev = r
    # the policy's decision is the first cycle the wheels decelerate to rest from: at rest minus the ramp
    return {"restart_bridge_at_rest_s": rest_t, "restart_bridge_wheels_slowing_s": _policy_stop(after, before, t_cmd)}


def _policy_stop(after, before, t_cmd) -> float:
    """Simulation seconds from the last command to the first cycle whose encoder speed drops (the timeout
    replacing it by V = W = 0)."""
    rows = np.vstack([before[-3:], after])
    ticks = np.abs(np.diff(rows[:, 3])) + np.abs(np.diff(rows[:, 4]))
    base = ticks[:2].mean() if len(ticks) >= 2 else 0.0
    for i in range(2, len(ticks)):
        if ticks[i] < 0.7 * base:
            return rows[i, 2] / 1000 - t_cmd  # the cycle ending at rows[i + 1] started at rows[i]
    return float("nan")


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
        raise RuntimeError(f"{name}: {msg['error']}")
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
    if simtwo:
        res = simtwo_side.result(res)
    print(table(res))
    if out_dir is not None:
        (out_dir / "faults_table.md").write_text(table(res) + "\n")
    res["notes"] = "; ".join(notes) + (f"; logs in {log_dir}" if notes else "")
    return res
