"""The soak part of ``raf experiment faults`` (issue 22, item 3): the whole stack as SimTwo runs it, for an hour.

``raf sim`` in its default, SimTwo-like mode (free-running, paced to the wall clock, camera, LIDAR and factory
server on), ``raf bridge``, ``raf localize`` and ``raf agent`` playing competition rounds one after another,
on a private roscore on loopback. A UDP proxy in this process (:class:`._faults_net.Proxy`) sits between the
simulator and the bridge and records every SensorFrame and every Command (the observer's view of the loop).

Rounds. The agent plays a round (rounds 1, 2, 3, 1, ... with seeds 0, 1, 2, ...); the round ends when the
agent logs ``task: done`` (plus :data:`DONE_GRACE`) or when the round's time (``FULL_DURATION`` of
:mod:`._competition_full`) is over. Then its score is read from the simulator's control channel, the agent is
stopped (SIGINT), the simulation paused and reset to the next round through the bridge's ``sim/pause`` and
``sim/reset`` services (``raf sim`` keeps running: a new scene, Seq and time from 0), a new ``raf agent``
started (each round a fresh start of the robot's program, as at the competition) and the simulation resumed.
The simulator, the bridge (and its camera child), the localization and roscore run for the whole soak.

Sampled every :data:`SAMPLE_EVERY` wall seconds: resident memory and CPU time (``/proc/PID/stat`` utime +
stime: % of one core) of each process; the observer's node counts the messages of ``odom``, ``/clock``,
``scan``, ``camera/image_raw``, ``pose`` (the localization's) and ``cmd_vel`` (the agent's).

**The loop latency in control cycles**: for each ``cmd_vel`` the agent publishes with a new value, the
SensorFrame its input came from (the ``pose`` it had: the newest the observer had received when the command
arrived, whose stamp is that frame's ``Tms``: Seq = Tms / 40 ms - 1) and the first Command the bridge sent
with that value (the proxy's record: its ``Seq`` is the SensorFrame it answers); latency = that Command's Seq -
the input frame's Seq. The simulator runs the Command in the cycle after the one it answers (SimTwo's script
reads it at its next call): the command acts ``latency + 1`` cycles after the frame it was computed from.

Windows. The first :data:`WARMUP` of the soak is warm-up; **start** is the window from there to
:data:`START_END`, **end** the last :data:`END_WINDOW`. Memory growth: each long-lived process's median RSS in
the end window against the start window (the agent, restarted each round: its RSS at the end of each round,
the last rounds against the first). CPU, message rates (per wall second, the reset gaps between rounds left
out) and the loop latency: each in the start and in the end window. Targets (:data:`TARGETS`): memory growth
< 5 %; every rate at the end within :data:`RATE_TOLERANCE` of the start's; the loop latency's median at the
end no more than the start's (whole cycles) and its 95th percentile at most one cycle more; no process died;
the rounds scored (a sanity figure). Everything is also written to ``soak/series.json`` (the samples and the
rounds) for plotting.
"""
from __future__ import annotations

import json
import math
import os
import re
import socket
import threading
import time
from pathlib import Path

import numpy as np

SAMPLE_EVERY = 5.0  # wall s between samples of memory and CPU
WARMUP = 0.15  # share of the soak before the start window (imports, caches, the first round's planning)
START_END = 0.40  # the start window ends here (share of the soak)
END_WINDOW = 0.25  # the end window: the last quarter
RATE_TOLERANCE = 0.10  # relative: a rate at the end may differ this much from the start's (see TARGETS)
DONE_GRACE = 3.0  # wall s after the agent's "task: done" before the round is closed
START_AFTER = 3.0  # simulated s of each round before the run starts (the server says STOP)
ROUNDS = (1, 2, 3)
TOPICS = ("odom", "/clock", "scan", "camera/image_raw", "pose", "cmd_vel")
LONG_LIVED = ("sim", "bridge", "bridge_camera", "localize", "roscore")

TARGETS = {
    "soak_rss_growth_max_pct": "< 5 % after warm-up (the long-lived processes; the agent: round to round)",
    "soak_queue_lag_late_s": "<= 1 s (simulation): odom and images keep up, no growing queue",
    "soak_rate_change_max_pct": "<= 10 % (every topic's rate at the end against the start's, reset gaps left out)",
    "soak_loop_latency_end_median_cycles": "<= the start's median (SensorFrame -> the Command with the agent's "
                                           "answer)",
    "soak_loop_latency_end_p95_cycles": "<= the start's p95 + 1 cycle",
    "soak_processes_died": "0",
    "soak_rounds_played": ">= 1, each scoring (a sanity figure: the stack plays)",
}


def rss_kib(pid: int) -> int | None:
    """Resident memory of a process (KiB), None when it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def cpu_ticks(pid: int) -> int | None:
    """utime + stime of a process (clock ticks), None when it is gone."""
    try:
        f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return int(f[11]) + int(f[12])
    except (OSError, IndexError, ValueError):
        return None


def children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def tree(pid: int) -> list[int]:
    """``pid`` and its descendants."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children(p))
    return out


def seq_of_ms(tms: int, period_ms: int = 40) -> int:
    """The Seq of the SensorFrame whose Tms is ``tms`` (Seq 0 has Tms = one period)."""
    return int(round(tms / period_ms)) - 1


class Observer:
    """This process's node: counts what the stack publishes (arrival wall times), keeps ``pose`` stamps and
    ``cmd_vel`` values for the loop latency and the last odom / image stamps for the queue lag."""

    def __init__(self):
        from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Image, LaserScan

        from ..ros.mw import QoS
        from ..ros.mw.base import stamp_ns
        from ._faults_watch import experiment_node

        self.node = node = experiment_node()
        self._ms = lambda stamp: int(round(stamp_ns(stamp) / 1e6))
        self.lock = threading.Lock()
        self.arrivals: dict[str, list[float]] = {t: [] for t in TOPICS}
        self.poses: list[tuple[float, int]] = []  # (wall, stamp ms)
        self.cmds: list[tuple[float, float, float]] = []  # (wall, v, w)
        self.last_odom_ms = self.last_image_ms = 0

        def count(topic, extra=None):
            def cb(m):
                now = time.monotonic()
                with self.lock:
                    self.arrivals[topic].append(now)
                    if extra is not None:
                        extra(now, m)
            return cb

        def odom(now, m):
            self.last_odom_ms = self._ms(m.header.stamp)

        def image(now, m):
            self.last_image_ms = self._ms(m.header.stamp)

        def pose(now, m):
            self.poses.append((now, self._ms(m.header.stamp)))

        def cmd(now, m):
            self.cmds.append((now, float(m.linear.x), float(m.angular.z)))

        self.subs = [node.subscribe("odom", Odometry, count("odom", odom), QoS.SYNCHRONOUS, 50),
                     node.subscribe("/clock", Clock, count("/clock"), QoS.SYNCHRONOUS, 50),
                     node.subscribe("scan", LaserScan, count("scan"), QoS.SYNCHRONOUS, 10),
                     node.subscribe("camera/image_raw", Image, count("camera/image_raw", image), QoS.RELIABLE, 2,
                                    large=True),
                     node.subscribe("pose", PoseWithCovarianceStamped, count("pose", pose), QoS.SYNCHRONOUS, 50),
                     node.subscribe("cmd_vel", Twist, count("cmd_vel", cmd), QoS.SYNCHRONOUS, 50)]

    def call(self, service: str, srv_name: str, timeout: float = 20.0, **fields):
        from ..ros.mw import api

        return self.node.call(service, getattr(api().srv_types(), srv_name), timeout=timeout, **fields)

    def close(self) -> None:
        for s in self.subs:
            self.node.close(s)


class SoakRig:
    """roscore, bridge, localization, agent, proxy and raf sim (realtime, camera, LIDAR, server, control)."""

    def __init__(self, args, log_dir: Path):
        from ..ros.master import PrivateMaster, free_port
        from ..ros.processes import Procs
        from ._faults_net import LOCAL, Proxy

        self.args, self.log_dir = args, log_dir
        self.master = PrivateMaster().start()
        self.env = self.master.env(MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
        self.procs = Procs(log_dir, env=self.env, numbered_logs=True)  # agent.1.log, agent.2.log, ...
        udp = lambda: free_port(socket.SOCK_DGRAM)  # noqa: E731
        self.bport, self.sport, self.ctl, self.server = udp(), udp(), udp(), udp()
        self.cam = f"tcp://{LOCAL}:{free_port()}"
        self.local = LOCAL
        self.proxy = Proxy((LOCAL, self.bport), seed=args.seed)
        self.obs: Observer | None = None

    def field_args(self) -> list[str]:
        return ["--field", self.args.field]

    def start_agent(self):
        p = self.procs.raf("agent", *self.field_args(), "agent", "--set", f"server.port={self.server}")
        self.wait_logged("agent", " running (field ", 90.0)
        return p

    def wait_logged(self, name: str, text: str, timeout: float) -> None:
        from ..ros.processes import wait_until

        wait_until(lambda: text in self.procs.log(name), timeout, f"{name} to log {text!r}", self.check, period=0.1)

    def check(self) -> None:
        for name in ("sim", "bridge", "localize", "agent"):
            p = self.procs.get(name) if name in self.procs else None
            if p is not None and p.poll() is not None:
                raise ProcessDied(name, p.returncode, self.procs.tail(name, 30))
        if self.master.proc is not None and self.master.proc.poll() is not None:
            raise ProcessDied("roscore", self.master.proc.returncode, "")

    def up(self, round_no: int, seed: int) -> "SoakRig":
        self.procs.raf("bridge", *self.field_args(), "bridge", "--port", str(self.bport), "--sim-host", self.local,
                       "--camera", self.cam, "--set", f"simulator/control={self.local}:{self.ctl}")
        self.procs.raf("localize", *self.field_args(), "localize")
        self.master.use_in_this_process()
        self.obs = Observer()
        self.start_agent()
        self.procs.raf("sim", *self.field_args(), "sim", "--port", str(self.sport), "--bridge",
                       f"{self.local}:{self.proxy.port}", "--camera-bind", self.cam, "--server-port", str(self.server),
                       "--control-port", str(self.ctl), "--round", str(round_no), "--seed", str(seed),
                       "--start-after", str(START_AFTER), "--status-every", "10")
        from ..ros.processes import wait_until

        wait_until(lambda: len(self.obs.arrivals["odom"]) > 5, 120, "odom from the bridge", self.check, period=0.1)
        return self

    def control(self, op: str, **fields) -> dict:
        from ..sim.control import ControlClient

        return ControlClient((self.local, self.ctl), timeout=2.0).request(op, **fields)

    def down(self) -> None:
        try:
            if self.obs is not None:
                self.obs.close()
        finally:
            self.procs.stop_all()
            self.proxy.close()
            self.master.cleanup()


class ProcessDied(RuntimeError):
    def __init__(self, name: str, code, tail: str):
        super().__init__(f"{name} exited with code {code}:\n{tail[-2000:]}")
        self.name = name


_SCORE = re.compile(r"score (\d+|-)/(\d+)")


def _score(state: dict) -> tuple[int, int]:
    m = _SCORE.search(state.get("score", ""))
    if not m:
        return 0, 0
    return (0 if m.group(1) == "-" else int(m.group(1))), int(m.group(2))


def part_soak(args, log_dir: Path, robot) -> dict:
    from ._competition_full import FULL_DURATION

    d = log_dir / "soak"
    d.mkdir(parents=True, exist_ok=True)
    duration = args.soak_sim_seconds if args.soak_sim_seconds is not None else args.soak_minutes * 60
    rounds: list[dict] = []
    samples: list[dict] = []  # {"t": wall s since start, "rss": {name: KiB}, "cpu": {name: ticks}}
    gaps: list[tuple[float, float]] = []  # wall (monotonic) intervals between rounds: left out of the rates
    lags: list[tuple[float, float, float]] = []  # (t, odom lag s, image lag s) behind the simulator's last frame
    died: list[str] = []
    note = ""
    k = 0
    rig = SoakRig(args, d)
    wall0 = time.monotonic()
    try:
        rig.up(ROUNDS[0], 0)
        obs, px = rig.obs, rig.proxy
        wall0 = time.monotonic()
        roscore = rig.master.proc.pid
        round_t0, done_at = time.monotonic(), None
        next_sample = wall0
        while True:
            now = time.monotonic()
            try:
                rig.check()
            except ProcessDied as e:
                died.append(e.name)
                note = str(e)
                break
            if now >= next_sample:
                next_sample += SAMPLE_EVERY
                pids = {n: rig.procs.get(n).pid for n in ("sim", "bridge", "localize", "agent")}
                cam = children(pids["bridge"])
                if cam:
                    pids["bridge_camera"] = cam[0]
                s = {"t": round(now - wall0, 2), "rss": {}, "cpu": {}, "pid": dict(pids)}
                for n, p in pids.items():
                    s["rss"][n], s["cpu"][n] = rss_kib(p), cpu_ticks(p)
                core = tree(roscore)  # roscore, rosmaster, rosout
                rs = [rss_kib(p) for p in core]
                cs = [cpu_ticks(p) for p in core]
                s["rss"]["roscore"] = sum(r for r in rs if r)
                s["cpu"]["roscore"] = sum(c for c in cs if c)
                samples.append(s)
                with px.lock:
                    t_ms = px.frames[-1][2] if px.frames else 0
                with obs.lock:
                    if obs.last_odom_ms and obs.last_image_ms and not _in_gaps(now, gaps, pad=3.0):
                        lags.append((now - wall0, (t_ms - obs.last_odom_ms) / 1000, (t_ms - obs.last_image_ms) / 1000))
            if done_at is None and "task: done" in rig.procs.log("agent"):
                done_at = now
            with px.lock:
                sim_t = px.frames[-1][2] / 1000 if px.frames else 0.0
            r_no = ROUNDS[k % len(ROUNDS)]
            over = (done_at is not None and now - done_at >= DONE_GRACE) or sim_t >= FULL_DURATION[r_no]
            if now - wall0 >= duration:
                break
            if not over:
                time.sleep(0.2)
                continue
            try:
                k = _next_round(rig, k, r_no, sim_t, now, wall0, round_t0, done_at, rounds, gaps)
            except ProcessDied as e:
                died.append(e.name)
                note = f"between rounds: {e}"
                break
            except Exception as e:  # noqa: BLE001 - the soak ends here; its figures so far are still reported
                note = f"between rounds: {type(e).__name__}: {e}"
                break
            round_t0, done_at = time.monotonic(), None
        wall = time.monotonic() - wall0
        diag = _bridge_counters(rig)
        with obs.lock:
            arrivals = {t: list(v) for t, v in obs.arrivals.items()}
            poses, cmds = list(obs.poses), list(obs.cmds)
        with px.lock:
            frames = [(f[0], f[1], f[2]) for f in px.frames]
            replies = list(px.replies)
    finally:
        rig.down()
    # the records first (the figures can be computed again from them: :func:`figures_from`)
    (d / "series.json").write_text(json.dumps({"wall0": wall0, "wall": wall, "samples": samples, "rounds": rounds,
                                               "gaps": gaps, "lags": lags, "died": died}))
    np.savez_compressed(d / "records.npz", poses=np.array(poses, float).reshape(-1, 2),
                        cmds=np.array(cmds, float).reshape(-1, 3), frames=np.array(frames, float).reshape(-1, 3),
                        replies=np.array(replies, float).reshape(-1, 4),
                        **{f"arrivals_{t.strip('/').replace('/', '_')}": np.array(v, float) for t, v in arrivals.items()})
    out = figures(wall0, wall, samples, rounds, gaps, lags, arrivals, poses, cmds, frames, replies, died)
    out.update(diag)
    if note:
        out["soak_note"] = note.splitlines()[0]
    return out


def _next_round(rig: SoakRig, k: int, r_no: int, sim_t: float, now: float, wall0: float, round_t0: float,
                done_at, rounds: list, gaps: list) -> int:
    """Close round ``k`` (its score from the control channel), then start round ``k + 1``: the agent stopped,
    the simulation paused and reset, a new agent, the simulation resumed. Returns ``k + 1``."""
    from ..ros.processes import wait_until

    obs = rig.obs
    st = rig.control("get_state")
    pts, mx = _score(st)
    last = re.search(r"last at ([\d.]+) s", st.get("score", ""))
    agent_pid = rig.procs.get("agent").pid
    rounds.append({"round": r_no, "seed": k, "points": pts, "max_points": mx,
                   "last_score_s": float(last.group(1)) if last else None, "agent_done": done_at is not None,
                   "sim_s": round(sim_t, 2), "wall_s": round(now - round_t0, 1),
                   "agent_rss_kib": rss_kib(agent_pid), "ended_at_s": round(now - wall0, 1)})
    print(f"soak: round {r_no} seed {k}: {pts}/{mx}, last at {rounds[-1]['last_score_s']} s "
          f"({now - wall0:.0f} s into the soak)", flush=True)
    g0 = time.monotonic()
    k += 1
    rig.procs.stop("agent")
    _ok(obs.call("sim/pause", "Trigger"), "sim/pause")
    _ok(obs.call("sim/reset", "ResetSimulation", round=ROUNDS[k % len(ROUNDS)], set_seed=True, seed=k), "sim/reset")
    rig.start_agent()  # (after the reset: its clock starts with the new round's)
    _ok(obs.call("sim/resume", "Trigger"), "sim/resume")
    n0 = len(obs.arrivals["odom"])
    wait_until(lambda: len(obs.arrivals["odom"]) > n0 + 5, 30, "odom after the reset", rig.check, 0.1)
    gaps.append((g0, time.monotonic() + 1.0))  # (+1 s: the first frames of the new round)
    return k


def _ok(resp, what: str) -> None:
    if not resp.success:
        raise RuntimeError(f"{what}: {resp.message}")


def _in_gaps(t: float, gaps, pad: float = 0.0) -> bool:
    return any(a - pad <= t <= b + pad for a, b in gaps)


def _bridge_counters(rig: SoakRig) -> dict:
    """The bridge's stream counters from its ``/diagnostics`` (its own account, for reference)."""
    from diagnostic_msgs.msg import DiagnosticArray

    from ..ros.messages import diagnostic_values
    from ..ros.mw import QoS

    got: dict = {}
    ev = threading.Event()

    def cb(m):
        for st in m.status:
            if st.name.endswith("sensor stream"):
                got.update(diagnostic_values(st))
                ev.set()

    sub = rig.obs.node.subscribe("/diagnostics", DiagnosticArray, cb, QoS.RELIABLE, 20)
    ev.wait(5.0)
    rig.obs.node.close(sub)
    out = {}
    for key in ("accepted", "lost", "duplicates", "stale", "restarts"):
        if key in got:
            try:
                out[f"soak_bridge_{key}"] = int(float(got[key]))
            except ValueError:
                pass
    return out


def _windows(wall0: float, wall: float) -> dict[str, tuple[float, float]]:
    """The start and end windows (monotonic wall times)."""
    return {"start": (wall0 + WARMUP * wall, wall0 + START_END * wall),
            "end": (wall0 + (1 - END_WINDOW) * wall, wall0 + wall)}


def _rate(times: list[float], lo: float, hi: float, gaps) -> float:
    """Messages per wall second in [lo, hi], the gaps left out (of the count and of the time)."""
    span = hi - lo - sum(max(0.0, min(b, hi) - max(a, lo)) for a, b in gaps)
    if span <= 0:
        return math.nan
    t = np.asarray(times, dtype=float)
    keep = (t >= lo) & (t <= hi)
    for a, b in gaps:
        keep &= ~((t >= a) & (t <= b))
    return int(keep.sum()) / span


def loop_latencies(poses, cmds, frames, replies, gaps) -> list[tuple[float, int]]:
    """(wall, cycles) per agent command with a new value: the Seq of the first Command carrying it minus the Seq
    of the SensorFrame of the pose the agent had (the observer's newest pose when the command arrived)."""
    import bisect

    pose_t = [p[0] for p in poses]
    rep_t = [r[0] for r in replies]
    out, prev = [], None
    for t, v, w in cmds:
        key = (v, w)
        if key == prev or (v == 0.0 and w == 0.0):
            prev = key
            continue
        prev = key
        if _in_gaps(t, gaps, pad=1.0):
            continue
        i = bisect.bisect_right(pose_t, t) - 1
        if i < 0:
            continue
        seq_in = seq_of_ms(poses[i][1])
        j = bisect.bisect_left(rep_t, t - 0.1)  # the bridge may answer with it before the observer sees it
        while j < len(replies) and replies[j][0] <= t + 1.0:
            _, seq, rv, rw = replies[j]
            if seq >= 0 and math.isclose(rv, v, rel_tol=1e-6, abs_tol=1e-9) and \
                    math.isclose(rw, w, rel_tol=1e-6, abs_tol=1e-9):
                if 0 <= seq - seq_in < 50:  # the same stream (not across a reset)
                    out.append((t, seq - seq_in))
                break
            j += 1
    return out


def figures_from(soak_dir: Path) -> dict:
    """The figures again from a soak's ``series.json`` and ``records.npz`` (e.g. after a change of the
    analysis)."""
    d = json.loads((Path(soak_dir) / "series.json").read_text())
    r = np.load(Path(soak_dir) / "records.npz")
    arrivals = {t: r[f"arrivals_{t.strip('/').replace('/', '_')}"].tolist() for t in TOPICS}
    return figures(d["wall0"], d["wall"], d["samples"], d["rounds"], [tuple(g) for g in d["gaps"]],
                   [tuple(x) for x in d["lags"]], arrivals, [tuple(x) for x in r["poses"].tolist()],
                   [tuple(x) for x in r["cmds"].tolist()], [tuple(x) for x in r["frames"].tolist()],
                   [(a, int(b), c, e) for a, b, c, e in r["replies"].tolist()], list(d["died"]))


def _pct(values, q) -> float:
    return float(np.percentile(values, q)) if len(values) else math.nan


def figures(wall0, wall, samples, rounds, gaps, lags, arrivals, poses, cmds, frames, replies, died) -> dict:
    win = _windows(wall0, wall)
    hz = os.sysconf("SC_CLK_TCK")
    sim_s = 0.04 * len(frames)
    out: dict = {"soak_mode": "stand-in raf sim, realtime, free-running (SimTwo-like defaults: camera, LIDAR, "
                              "factory server), bridge, localize, agent playing rounds",
                 "soak_wall_seconds": round(wall, 1), "soak_sim_seconds": round(sim_s, 1),
                 "soak_realtime_factor": round(sim_s / wall, 3) if wall > 0 else math.nan,
                 "soak_samples": len(samples)}
    # ---------------------------------------------------------------- processes: memory, CPU
    rel = {n: (a - wall0, b - wall0) for n, (a, b) in win.items()}
    worst, died_n = 0.0, len(died)
    for n in LONG_LIVED:
        pids = {s["pid"].get(n) for s in samples if n in s.get("pid", {})} if n != "roscore" else set()
        if len(pids) > 1:
            died_n += 1  # a long-lived process started again: it died
            died.append(n)
        for w, (a, b) in rel.items():
            rss = [s["rss"][n] for s in samples if a <= s["t"] <= b and s["rss"].get(n)]
            if rss:
                out[f"soak_rss_{n}_{w}_mib"] = round(float(np.median(rss)) / 1024, 1)
            cpu = [(s["t"], s["cpu"][n]) for s in samples if a <= s["t"] <= b and s["cpu"].get(n) is not None]
            if len(cpu) >= 2 and cpu[-1][0] > cpu[0][0]:
                out[f"soak_cpu_{n}_{w}_pct"] = round(100.0 * (cpu[-1][1] - cpu[0][1]) / hz / (cpu[-1][0] - cpu[0][0]), 1)
        a0, a1 = out.get(f"soak_rss_{n}_start_mib"), out.get(f"soak_rss_{n}_end_mib")
        if a0 and a1:
            g = 100.0 * (a1 - a0) / a0
            out[f"soak_rss_{n}_growth_pct"] = round(g, 2)
            worst = max(worst, g)
    # the agent: one process per round; its CPU per round window, its RSS at the end of each round
    for w, (a, b) in rel.items():
        per = {}
        for s in samples:
            if a <= s["t"] <= b and s["cpu"].get("agent") is not None:
                per.setdefault(s["pid"]["agent"], []).append((s["t"], s["cpu"]["agent"]))
        ticks = sum(v[-1][1] - v[0][1] for v in per.values() if len(v) >= 2)
        span = sum(v[-1][0] - v[0][0] for v in per.values() if len(v) >= 2)
        if span > 0:
            out[f"soak_cpu_agent_{w}_pct"] = round(100.0 * ticks / hz / span, 1)
    agent_rss = [r["agent_rss_kib"] for r in rounds if r.get("agent_rss_kib")]
    if len(agent_rss) >= 2:
        m = max(1, len(agent_rss) // 4)
        a0, a1 = float(np.median(agent_rss[:m])), float(np.median(agent_rss[-m:]))
        out["soak_rss_agent_start_mib"], out["soak_rss_agent_end_mib"] = round(a0 / 1024, 1), round(a1 / 1024, 1)
        g = 100.0 * (a1 - a0) / a0
        out["soak_rss_agent_growth_pct"] = round(g, 2)
        worst = max(worst, g)
    out["soak_rss_growth_max_pct"] = round(worst, 2)
    out["soak_rss_growth_max_target_met"] = worst < 5.0
    # ---------------------------------------------------------------- message rates
    change = 0.0
    for topic in TOPICS:
        name = topic.strip("/").replace("/", "_")
        r = {w: _rate(arrivals[topic], a, b, gaps) for w, (a, b) in win.items()}
        out[f"soak_rate_{name}_start_hz"], out[f"soak_rate_{name}_end_hz"] = round(r["start"], 2), round(r["end"], 2)
        if r["start"] > 0 and math.isfinite(r["end"]):
            change = max(change, abs(r["end"] - r["start"]) / r["start"])
        else:
            change = math.inf
    out["soak_rate_change_max_pct"] = round(100.0 * change, 2) if math.isfinite(change) else -1.0
    out["soak_rate_change_max_target_met"] = math.isfinite(change) and change <= RATE_TOLERANCE
    # ---------------------------------------------------------------- the loop latency
    lat = loop_latencies(poses, cmds, frames, replies, gaps)
    for w, (a, b) in win.items():
        v = [c for t, c in lat if a <= t <= b]
        out[f"soak_loop_latency_{w}_samples"] = len(v)
        out[f"soak_loop_latency_{w}_median_cycles"] = _pct(v, 50)
        out[f"soak_loop_latency_{w}_p95_cycles"] = _pct(v, 95)
        out[f"soak_loop_latency_{w}_max_cycles"] = float(max(v)) if v else math.nan
    s_med, e_med = out["soak_loop_latency_start_median_cycles"], out["soak_loop_latency_end_median_cycles"]
    s95, e95 = out["soak_loop_latency_start_p95_cycles"], out["soak_loop_latency_end_p95_cycles"]
    out["soak_loop_latency_end_median_cycles_target_met"] = bool(e_med <= s_med) if math.isfinite(e_med) else False
    out["soak_loop_latency_end_p95_cycles_target_met"] = bool(e95 <= s95 + 1) if math.isfinite(e95) else False
    # ---------------------------------------------------------------- queues
    late = [x for x in lags if x[0] >= (1 - END_WINDOW) * wall]
    early = [x for x in lags if WARMUP * wall <= x[0] <= START_END * wall]
    for key, sel in (("early", early), ("late", late)):
        for i, n in ((1, "odom"), (2, "image")):
            out[f"soak_{n}_lag_{key}_s"] = round(float(np.median([x[i] for x in sel])), 3) if sel else math.nan
    q = max(out["soak_odom_lag_late_s"], out["soak_image_lag_late_s"])
    out["soak_queue_lag_late_s"] = q
    out["soak_queue_lag_late_target_met"] = bool(q <= 1.0)
    # ---------------------------------------------------------------- processes, rounds
    out["soak_processes_died"] = died_n
    out["soak_processes_died_names"] = ",".join(sorted(set(died)))
    out["soak_processes_died_target_met"] = died_n == 0
    out["soak_rounds_played"] = len(rounds)
    out["soak_rounds_at_max"] = sum(r["points"] == r["max_points"] > 0 for r in rounds)
    out["soak_rounds_points"] = sum(r["points"] for r in rounds)
    out["soak_rounds_max_points"] = sum(r["max_points"] for r in rounds)
    out["soak_rounds_min_points"] = min((r["points"] for r in rounds), default=0)
    out["soak_rounds_played_target_met"] = bool(rounds) and all(r["points"] > 0 for r in rounds)
    out["soak_frames_sent_by_sim"] = len(frames)
    return out
