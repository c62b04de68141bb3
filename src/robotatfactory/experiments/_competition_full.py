"""One round of ``raf experiment competition`` over the whole stack (mode ``full_stack``).

Each run is its own private graph (a roscore on a free port, or a free ROS 2 domain: the middleware of the
interpreter, ``raf --middleware ros2 experiment competition`` for ROS 2) and its own ports:
``raf sim`` (realtime, SimTwo-like defaults, camera and LIDAR, ``--trace`` and ``--end-after-max``),
``raf bridge``, ``raf localize``, ``raf agent`` (the EKF's ``pose`` only) and ``raf record`` (the ``pose``
topic the agent gets, for measuring). Nothing of the robot's side sees the ground truth: the experiment
reads the simulator's trace after the run. The bridge and the localizer get the run's camera calibration
(``--calibration FILE``) when the experiment made or was given one (:mod:`._competition_calibration`).

Measured per run: the score, maximum and last-delivery time (``raf sim``'s final report), rule notes,
picks and places from the agent's log, collisions, pushes and odometry slip from the trace
(:class:`._competition_observe.RunObserver`, as in bare_truth), and **the pose error**: the agent's
``pose`` input against the ground truth at the pose's stamp, over the whole run and while it picks or
places (from the agent's ``docking to ...`` event to the pick's or place's outcome): the issue's target
is at most 2 cm then.
"""
from __future__ import annotations

import math
import re
import socket
import statistics
import tempfile
import time
from pathlib import Path

from ..ros.master import free_port
from ..agent.behaviour import recovery_counts
from ._competition_observe import SPIN_AFTER

FULL_DURATION = {1: 130.0, 2: 190.0, 3: 230.0}  # simulated s of one run at most (raf sim --duration)
START_AFTER = 3.0  # simulated s before the run starts (the agent's nodes are up by then)
END_AFTER_MAX = 1.0  # simulated s the maximum score must stand before raf sim ends the run
DONE_GRACE = 3.0  # wall s after the agent logged "task: done" before raf sim is stopped
PLACE_HEADING_AFTER = 0.3  # s into a place's docking: the heading error there (place_heading_error_deg)
TURN_HEADING_WINDOW = 0.2  # s: a carrying turn's estimate is the median heading error over this, SPIN_AFTER after it
#: every process of a run: OpenCV's own thread pool off (one thread per process; the runs of a batch are the
#: parallelism). Measured alone, paced, round 1 seed 100, ROS 1: 42-46 CPU s with the pool, 39-40 without, the
#: same trace byte for byte (docs/benchmarks.md)
RUN_ENV = {"OPENCV_FOR_THREADS_NUM": "1"}
#: paced: wall s raf sim waits for a reply (then --on-timeout stop): above the nodes' own safety net (5 s)
PACED_REPLY_TIMEOUT = 15.0

_EVENT = re.compile(r"raf agent: t = ([\d.]+) s: (.*)$", re.M)
_DOCK_END = re.compile(r"^(picked |placed |pick at |place at |timeout: )")


def agent_events(text: str) -> list[tuple[float, str]]:
    """(t, text) of every event in ``raf agent``'s log, in order."""
    return [(float(t), e.strip()) for t, e in _EVENT.findall(text)]


def dock_windows(events: list[tuple[float, str]]) -> list[tuple[float, float, str]]:
    """(t0, t1, what) while the agent picks or places: from its ``docking to ...`` event to the next event
    that ends the docking (picked, placed, failed, timeout); an unfinished one ends at inf."""
    out = []
    for i, (t0, text) in enumerate(events):
        if not text.startswith("docking to "):
            continue
        t1 = next((t for t, e in events[i + 1:] if _DOCK_END.match(e) or e.startswith("docking to ")), math.inf)
        out.append((t0, t1, text[len("docking to "):]))
    return out


def pose_errors(poses: list[tuple[float, float, float, float]], trace) -> list[tuple[float, float, float]]:
    """(stamp, position error m, heading error rad) of each pose ``(stamp, x, y, theta)`` against the
    trace's ground truth at that stamp (poses outside the trace are left out)."""
    from ..localization.geometry import wrap_angle

    out = []
    for t, x, y, th in poses:
        g = trace.pose_at(t)
        if g is not None:
            out.append((t, math.hypot(x - g[0], y - g[1]), abs(wrap_angle(th - g[2]))))
    return out


def heading_errors_in(errs: list[tuple[float, float, float]], spans, pick=lambda sel: sel[0]) -> list[float]:
    """The heading error (deg, unsigned) in each span ``(t0, t1)`` (``errs`` from :func:`pose_errors`), ``pick``
    of the span's errors (the first pose's by default); a span with no pose gives nothing."""
    out = []
    for t0, t1 in spans:
        sel = [e[2] for e in errs if t0 <= e[0] <= t1]
        if sel:
            out.append(round(math.degrees(pick(sel)), 3))
    return out


def place_heading_errors(errs: list[tuple[float, float, float]], windows: list[tuple[float, float, str]],
                         after: float = PLACE_HEADING_AFTER) -> list[float]:
    """The heading error (deg, unsigned) of the first pose ``after`` s or more into each place's docking (a
    ``docking to place`` window of :func:`dock_windows`): how far off the agent's heading was as it entered the
    place approach, where a turn with the part has just ended."""
    return heading_errors_in(errs, [(t0 + after, t1) for t0, t1, what in windows if what.startswith("place")])


def carry_turn_heading_errors(errs: list[tuple[float, float, float]], ends: list[float],
                              after: float = SPIN_AFTER, window: float = TURN_HEADING_WINDOW) -> list[float]:
    """The heading error (deg, unsigned) from ``after`` s after each turn on the spot with a part ended (``ends``:
    the observer's ``carry_turn_end_s``), the median over the poses of the next ``window`` s: the estimate when
    the turn's slip is measured, what ``ekf.carry_turn_bias`` is for. A median, because the robot often turns
    again by then, and one truth sample out of step with its stamp (SimTwo's frames) reads as degrees of error
    at a turn rate; a turn with no pose in the window gives nothing."""
    return heading_errors_in(errs, [(t + after, t + after + window) for t in ends], pick=statistics.median)


def read_poses(bag_path: Path, topic: str = "pose") -> list[tuple[float, float, float, float]]:
    """(stamp s, x, y, yaw) of every PoseWithCovarianceStamped on ``topic`` in the bag."""
    from ..ros.bags import find_topic, open_bag
    from ..ros.calibration_source import odom_pose

    with open_bag(bag_path) as bag:
        return sorted(odom_pose(m) for _topic, _t, m in bag.messages(find_topic(bag.topics, topic)))


def read_commands(bag_path: Path, topic: str = "cmd_vel") -> list[tuple[float, float, float]]:
    """(bag time s, v, w) of every Twist on ``topic``: bag time is the recorder's clock (simulation time)
    when the command was seen on the wire."""
    from ..ros.bags import find_topic, open_bag

    with open_bag(bag_path) as bag:
        names = find_topic(bag.topics, topic)
        return [(t * 1e-9, m.linear.x, m.angular.z) for _topic, t, m in bag.messages(names)]


SCAN_NO_FIX_CAUSES = ("too_few_returns", "too_few_on_map", "mostly_off_map")  # why a sweep gave no fix, counted per run


def read_status_counters(bag_path: Path, name: str, topic: str = "diagnostics") -> dict[str, int]:
    """Every integer value of the last status on ``topic`` whose name ends with ``name`` (``"raf agent"``: the
    agent's :class:`~robotatfactory.agent.behaviour.AgentCounters`, picks, choices made ahead, ...;
    ``": filter"``: the localizer's counts, LIDAR sweeps and what became of them)."""
    from ..ros.bags import find_topic, open_bag
    from ..ros.messages import diagnostic_values

    last = None
    with open_bag(bag_path) as bag:
        for _topic, _t, m in bag.messages(find_topic(bag.topics, topic)):
            last = next((s for s in m.status if s.name.endswith(name)), last)
    if last is None:
        raise ValueError(f"no status named ...{name!r} on {topic}")
    return {k: int(v) for k, v in diagnostic_values(last).items() if v.lstrip("-").isdigit()}


def scan_counts(counters: dict[str, int]) -> dict[str, int]:
    """What the localizer's LIDAR sweeps came to (``counters``: its filter status, :func:`read_status_counters`):
    ``scans`` taken, ``scan_fixes_accepted`` by the filter, and the sweeps the matcher gave no fix for want of
    returns (``scans_too_few_returns``: the robot's body and a held part hide the rest), of returns on the map
    (``scans_too_few_on_map``) or with most returns off it (``scans_mostly_off_map``: parts, another robot), and
    the matcher's fixes from every ray (``scan_fixes_every_ray``: ``scan_match.dense_when_few``, ``..._on_map``)."""
    return {"scans": counters["scans"], "scan_fixes_accepted": counters.get("filter_scan_accepted", 0),
            "scan_fixes_every_ray": counters.get("scan_fixes_every_ray", 0),
            **{f"scans_{k}": counters.get(f"scan_unmatched_{k}", 0) for k in SCAN_NO_FIX_CAUSES}}


def count_messages(bag_path: Path, topic: str) -> int:
    """How many messages on ``topic`` the bag holds (0 when it recorded none)."""
    from ..ros.bags import find_topic, open_bag

    with open_bag(bag_path) as bag:
        names = find_topic(bag.topics, topic)
        return sum(1 for _ in bag.messages(names)) if names else 0


def command_delays(commands: list[tuple[float, float, float]], trace) -> list[float]:
    """Seconds from each command's publication (its bag time) to the start of the first control cycle that
    ran it (the trace's ``cmd``): the loop's command latency. Commands never run (replaced before the next
    reply) and repeated values are left out."""
    import bisect

    rec, times = trace.records, trace.times
    period = float(trace.head.get("control_period", 0.04))
    out, prev = [], None
    for t, v, w in commands:
        key = (round(v, 4), round(w, 4))
        if key == prev:
            continue
        prev = key
        i = bisect.bisect_left(times, t)
        for r in rec[i:i + 4]:  # it runs within a few cycles or never
            if (round(r.cmd[0], 4), round(r.cmd[1], 4)) == key:
                out.append(r.t - period - t)
                break
    return out


class SimStartError(RuntimeError):
    """``raf sim`` exited at once (e.g. a port taken by another run in between): the run may be retried."""


def _udp_port() -> int:
    return free_port(socket.SOCK_DGRAM)


def play_full_stack(round_no: int, seed: int, out_dir: Path | None, record_path: bool = False,
                    field_name: str | None = None, simulator: str = "standin", localize: tuple[str, ...] = (),
                    agent: tuple[str, ...] = (), sim_set: tuple[str, ...] = (),
                    loss: tuple[float, float, float] = (0.0, 0.0, 0.0), calibration: str | None = None,
                    log_dir: Path | None = None, paced: bool = False, compose: bool = False) -> dict:
    """One round over the whole stack (see the module docstring); a flat dict of the run's figures, as
    :func:`.competition.play_round` gives (plus ``pose_error_*`` keys and ``logs``).

    ``simulator="simtwo"``: the real SimTwo (``raf simtwo run``, the round's parts in its scene, field
    ``simtwo2022``) instead of ``raf sim``, and ``raf referee`` (the factory, the machines, the score and the
    trace from the part positions SimTwo reports) instead of raf sim's own; the referee ends the run.

    ``sim_set``: raf sim ``--set`` items (the world's perturbation, ``perturb.field_mm=2``); ``loss``: (drop,
    duplicate, reorder) probabilities per datagram on the UDP link between the simulator and the bridge, both
    ways, through the faults experiment's proxy (:class:`._faults_net.Proxy`) when any is > 0; ``calibration``: a
    camera calibration YAML given to ``raf bridge --calibration`` and ``raf localize --calibration`` (None: the
    robot file's nominal camera; :mod:`._competition_calibration` makes it); ``log_dir``: the run's directory
    (default :func:`run_dir`); ``paced``: the whole loop paced by simulation time instead of the wall clock
    (``raf sim --paced --pace-hold 2`` and every node's ``pace.enabled``: docs/pacing.md), the stand-in only;
    ``compose``: the bridge, the localization and the agent as components of one process (``raf compose``,
    ROS 1), their messages in-process, instead of a process each."""
    from ..ros.master import private_graph
    from ..ros.mw import bag_format
    from ..ros.mw import name as middleware
    from ..ros.processes import Procs
    from ._competition_log import wait_for_report

    mw = middleware()
    fmt = bag_format(mw)  # a ROS 1 bag is a file; a rosbag2 a directory
    simtwo = simulator == "simtwo"
    if simtwo:
        from ..field import DEFAULT_FIELD
        from ..simtwo_linux.scene import field_for_simtwo

        field_name = field_for_simtwo(field_name or DEFAULT_FIELD)
    log_dir = Path(log_dir) if log_dir is not None else run_dir(out_dir, round_no, seed, simulator)
    trace_path = log_dir / TRACE_FILE
    bag_path = log_dir / (POSE_BAG_FILE if fmt == "bag" else POSE_BAG_DIR)
    # (each run's own, leased by proc.free_port; a port a stranger took makes raf sim exit at once:
    # SimStartError, retried)
    sim_port, bridge_port, server_port, cam_port = _udp_port(), _udp_port(), _udp_port(), free_port()  # (TCP)
    field_args = ["--field", field_name] if field_name else []
    calib_args = ["--calibration", str(calibration)] if calibration else []
    if paced and simtwo:
        raise ValueError("paced: the stand-in only (SimTwo runs in real time)")
    pace = ["--set", "pace.enabled=true"] if paced else []
    sim_pace = ["--paced", "--pace-hold", "2", "--lockstep-timeout", str(PACED_REPLY_TIMEOUT)] if paced else []
    wall0 = time.perf_counter()
    phases: dict[str, float] = {}  # wall s of starting the processes, the run, stopping them (and analysing)
    graph = private_graph(mw).start()
    nodes = ("stack",) if compose else ("bridge", "localize", "agent", "record")  # the processes of the nodes
    agent_log = "stack" if compose else "agent"  # the process whose log holds the agent's lines
    procs = Procs(log_dir, watch=nodes)
    proxy = None
    frames_to = bridge_port  # where the simulator sends its frames: the bridge, or the lossy link to it
    try:
        if any(loss):
            from ._faults_net import LOCAL, Proxy

            # paced, raf sim waits for the reply to every frame: the link tells it what it lost (simtwo.messages.LINK_LOST)
            proxy = Proxy((LOCAL, bridge_port), seed=1000 * round_no + seed, notify_lost=paced)
            proxy.set_faults(*loss)
            frames_to = proxy.port
        env = graph.env(**RUN_ENV)
        bridge_cmd = ["bridge", "--port", str(bridge_port), "--camera", f"tcp://127.0.0.1:{cam_port}", "--sim-host",
                      "127.0.0.1", *calib_args, *pace, *(["--set", "camera.process=bridge"] if compose else [])]
        localize_cmd = ["localize", *calib_args, *pace, *[a for s in localize for a in ("--set", s)]]
        agent_cmd = ["agent", "--set", f"server.port={server_port}", *pace, *[a for s in agent for a in ("--set", s)]]
        if not compose:
            procs.raf("bridge", *field_args, *bridge_cmd, env=env)
            procs.raf("localize", *field_args, *localize_cmd, env=env)
        # the pose and the commands (the figures), and what the filter made of each camera fix and its counters
        # (why a pose ran away: SimTwo, round 3, 55 mm off for 4 s at a std of 2-3 mm after a stall)
        record_cmd = ["record", "-o", str(bag_path), "--topics", "pose", "cmd_vel", "aruco/fixes/filter_accepted",
                      "aruco/fixes/filter_rejected", "diagnostics", "--format", fmt]
        if not compose:
            procs.raf("record", *record_cmd, env=env)
        if simtwo:  # the referee: raf sim's factory, referee and trace, from SimTwo's reports; it ends the run
            procs.raf("referee", *field_args, "referee", "--round", str(round_no), "--seed", str(seed),
                      "--start-after", str(START_AFTER), "--ready-topic", "pose",
                      "--duration", str(FULL_DURATION[round_no]),
                      "--server-port", str(server_port), "--trace", str(trace_path), "--end-after-max",
                      str(END_AFTER_MAX), "--status-every", "5", env=env, may_exit=True)
            _wait_logged(procs, "referee", "running", 60.0)
        if compose:
            procs.raf("stack", *field_args, "compose", "--", *bridge_cmd, "--", *localize_cmd, "--", *agent_cmd,
                      "--", *record_cmd, env=env)
        else:
            procs.raf("agent", *field_args, *agent_cmd, env=env)
        _wait_logged(procs, agent_log, "raf agent: raf_agent running", 60.0)
        if simtwo:
            procs.raf("sim", *field_args, "simtwo", "run", "--port", str(sim_port), "--bridge",
                      f"127.0.0.1:{frames_to}", "--camera-port", str(cam_port), "--round", str(round_no), "--seed",
                      str(seed), "--duration", str(FULL_DURATION[round_no] * 1.5 + 60.0), env=env, may_exit=True)
            _wait_logged(procs, "sim", "[simtwo] running", 120.0)
        else:
            procs.raf("sim", *field_args, "sim", "--round", str(round_no), "--seed", str(seed),
                      "--start-after", str(START_AFTER), "--duration", str(FULL_DURATION[round_no]),
                      "--port", str(sim_port), "--bridge", f"127.0.0.1:{frames_to}", "--camera-bind",
                      f"tcp://127.0.0.1:{cam_port}", "--server-port", str(server_port), "--no-control",
                      "--trace", str(trace_path), "--end-after-max", str(END_AFTER_MAX), "--status-every", "5",
                      *sim_pace, *[a for x in sim_set for a in ("--set", x)], env=env, may_exit=True)
        ender = "referee" if simtwo else "sim"  # the process that ends the run and writes the final report
        sim = procs.get(ender)
        started = time.monotonic()
        phases["start_s"] = time.perf_counter() - wall0
        limit = started + FULL_DURATION[round_no] * 1.5 + 60.0
        done_at = None
        while sim.poll() is None and time.monotonic() < limit:
            procs.check()
            if done_at is None and "task: done" in _read(log_dir / f"{agent_log}.log"):
                done_at = time.monotonic()  # the agent has nothing left to do: no need to wait out the round
            if done_at is not None and time.monotonic() - done_at > DONE_GRACE:
                break
            time.sleep(0.2)
        if sim.poll() is not None and sim.returncode != 0 and time.monotonic() - started < 20.0:
            raise SimStartError(f"raf {ender} could not start (exit code {sim.returncode}): {procs.tail(ender, 3)}")
        phases["run_s"] = time.perf_counter() - wall0 - phases["start_s"]
        procs.stop(ender)  # SIGINT: raf sim (raf referee) writes its final report on the way out
        wait_for_report(log_dir / f"{ender}.log")  # (then every node at once, raf record closing its bag)
    finally:
        procs.stop_all()
        graph.cleanup()
        if proxy is not None:
            proxy.close()
    phases["stop_s"] = time.perf_counter() - wall0 - phases.get("start_s", 0.0) - phases.get("run_s", 0.0)
    out = analyse(round_no, seed, log_dir, trace_path, bag_path, record_path, field_name,
                  wall_s=time.perf_counter() - wall0, middleware=mw, report_log=f"{ender}.log",
                  agent_log=f"{agent_log}.log")
    out.update({f"wall_{k}": round(v, 3) for k, v in phases.items()})
    out["wall_analyse_s"] = round(time.perf_counter() - wall0 - sum(phases.values()), 3)
    if proxy is not None:  # what the lossy link did (both directions)
        out["link"] = {k: int(proxy.counts.get(k, 0)) for k in ("frames", "replies", "dropped", "duplicated",
                                                               "reordered", "lost_notices")}
    return out


def run_dir(out_dir: Path | None, round_no: int, seed: int, simulator: str = "standin") -> Path:
    """The run's log directory (made): ``{out_dir}/full_r{round}_s{seed}`` (``simtwo_...`` on the real SimTwo),
    or a temporary one without ``out_dir``."""
    d = Path(out_dir) / run_dir_name(round_no, seed, simulator) if out_dir else Path(tempfile.mkdtemp(
        prefix="raf-comp-"))
    d.mkdir(parents=True, exist_ok=True)
    return d


def run_dir_name(round_no: int, seed: int, simulator: str = "standin") -> str:
    """The name of a run's log directory in the batch's ``--out`` (:func:`run_dir`)."""
    return f"{'simtwo' if simulator == 'simtwo' else 'full'}_r{round_no}_s{seed}"


#: the agent's trace in a run directory
TRACE_FILE = "trace.jsonl"
#: the recorded poses in a run directory: a ROS 1 bag is a file, a rosbag2 a directory
POSE_BAG_FILE, POSE_BAG_DIR = "pose.bag", "pose_bag"
#: what a round writes into its run directory that a second attempt would find there: the recorder never
#: overwrites a bag (a retry after SimStartError failed on the first attempt's pose.bag), and a trace would mix
ATTEMPT_OUTPUTS = (POSE_BAG_FILE, POSE_BAG_DIR, TRACE_FILE)


def kept_pose_bag(log_dir: Path) -> Path:
    """The pose recording a run left in ``log_dir``, whichever middleware recorded it."""
    log_dir = Path(log_dir)
    return log_dir / POSE_BAG_FILE if (log_dir / POSE_BAG_FILE).exists() else log_dir / POSE_BAG_DIR


def previous_outputs(out_dir: Path, runs: list[tuple[int, int]], simulator: str = "standin") -> list[Path]:
    """What an earlier batch left in ``out_dir`` that the runs ``(round, seed)`` of this one would meet in their
    directories (:data:`ATTEMPT_OUTPUTS`): the recorder never overwrites a bag, so each such run would fail."""
    return [p for r, s in runs for name in ATTEMPT_OUTPUTS
            if (p := Path(out_dir) / run_dir_name(r, s, simulator) / name).exists()]


def discard_attempt(log_dir: Path) -> None:
    """Remove what an attempt that could not start left in ``log_dir`` (:data:`ATTEMPT_OUTPUTS`) before the run
    is tried again; its logs are overwritten by the next attempt's."""
    import shutil

    for name in ATTEMPT_OUTPUTS:
        p = Path(log_dir) / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()


def _read(path: Path) -> str:
    try:
        return path.read_text(errors="replace")
    except OSError:
        return ""


def _wait_logged(procs, name: str, text: str, timeout: float) -> None:
    from ..ros.processes import wait_until

    wait_until(lambda: text in _read(procs.log_dir / f"{name}.log"), timeout, f"{name} to log {text!r}", procs.check)


def analyse(round_no: int, seed: int, log_dir: Path, trace_path: Path, bag_path: Path, record_path: bool,
            field_name: str | None, wall_s: float, middleware: str, report_log: str = "sim.log",
            agent_log: str = "agent.log") -> dict:
    """The run's figures from its logs, trace and bag (separate from running it, so a kept run's
    directory can be analysed again)."""
    from ..field import load_field
    from ..robot import load_robot
    from ..sim.trace import read_trace
    from ._competition_observe import RunObserver
    from ._competition_log import notes_of, parse_sim_report, points_lost

    text = _read(log_dir / report_log)
    agent_log = _read(log_dir / agent_log)
    points, max_points, last, found = parse_sim_report(text)
    notes = notes_of(text)
    world = re.findall(r"raf sim: world perturbed: .*?; offsets (\{.*\})", text)
    events = agent_events(agent_log)
    out = {"round": round_no, "seed": seed, "points": points, "max_points": max_points,
           "max_score": found and points == max_points, "last_score_s": last, "notes": notes,
           "points_lost": points_lost(text),
           "false_start": any("false start" in n.lower() for n in notes),
           "picks_attempted": sum(e.startswith(("picked ", "pick at ")) for _, e in events),
           "pick_failures": sum(bool(re.match(r"pick at .* failed", e)) for _, e in events),
           "places": sum(e.startswith("placed ") for _, e in events),
           "place_failures": sum(bool(re.match(r"place at .* failed", e)) for _, e in events),
           "timeouts": sum(e.startswith("timeout: ") for _, e in events), "no_path": 0,
           "agent_done": any(e == "task: done" for _, e in events), "wall_s": wall_s, "logs": str(log_dir),
           "middleware": middleware}
    if world:  # this run's draw of a world that is not the map (raf sim logs it)
        import json

        try:
            out["world"] = json.loads(world[-1])
        except ValueError:
            pass
    field, robot = (load_field(field_name) if field_name else load_field()), load_robot()
    try:
        trace = read_trace(trace_path)
    except (OSError, ValueError) as e:
        out["error"] = f"no ground-truth trace: {e}"
        return out
    obs = RunObserver(field, robot, record_path)
    for r in trace.records:
        obs.cycle(r.t, r.seq, r.pose, r.held, r.enc, r.parts)
    out.update(obs.figures())
    out["sim_s"] = trace.records[-1].t if trace.records else 0.0
    if record_path:
        out["events"] = [(round(t, 2), e, *(round(v, 4) for v in (trace.pose_at(t) or (math.nan,) * 3)[:2]))
                         for t, e in events]
    try:
        poses = read_poses(bag_path)
    except Exception as e:  # noqa: BLE001 - a missing or unreadable bag is a run without the measure, said so
        out["pose_error_note"] = f"no pose recording: {type(e).__name__}: {e}"
        poses = []
    try:
        delays = command_delays(read_commands(bag_path), trace)
    except Exception:  # noqa: BLE001 - as for the poses
        delays = []
    try:  # what the agent counted (its last /diagnostics): choices made ahead on the thread, ...
        counters = read_status_counters(bag_path, "raf agent")
        out["choices_ahead"] = counters["choices_ahead"]
        if "legs_ahead" in counters:  # (an agent before it had none)
            out["legs_ahead"] = counters["legs_ahead"]
        out["picks"] = counters["picks"]
        out.update(recovery_counts(counters))
    except Exception as e:  # noqa: BLE001 - as for the poses
        out["counters_note"] = f"no agent counters: {type(e).__name__}: {e}"
    try:  # the LIDAR sweeps and what the scan matcher and the filter made of them
        out.update(scan_counts(read_status_counters(bag_path, ": filter")))
    except Exception as e:  # noqa: BLE001 - as for the poses
        out["scan_counts_note"] = f"no localizer counts: {type(e).__name__}: {e}"
    try:  # the camera fixes the filter took and gated: how much the camera gave the localization
        out["camera_fixes_accepted"] = count_messages(bag_path, "aruco/fixes/filter_accepted")
        out["camera_fixes_rejected"] = count_messages(bag_path, "aruco/fixes/filter_rejected")
    except Exception:  # noqa: BLE001 - as for the poses
        pass
    out["command_delay_median_s"] = statistics.median(delays) if delays else math.nan
    out["command_delay_p95_s"] = _percentile(delays, 95)
    errs = pose_errors(poses, trace)
    windows = dock_windows(events)
    docking = [e for e in errs if any(t0 <= e[0] <= t1 for t0, t1, _ in windows)]
    out["pose_samples"] = len(errs)
    out["pose_samples_docking"] = len(docking)
    for key, sel in (("pose_error", errs), ("pose_error_docking", docking)):
        pos = [e[1] for e in sel]
        out[f"{key}_median_m"] = statistics.median(pos) if pos else math.nan
        out[f"{key}_max_m"] = max(pos) if pos else math.nan
        out[f"{key}_heading_max_rad"] = max((e[2] for e in sel), default=math.nan)
    out["pose_error_p95_m"] = _percentile([e[1] for e in errs], 95)
    out["place_heading_error_deg"] = place_heading_errors(errs, windows)
    out["carry_turn_heading_error_deg"] = carry_turn_heading_errors(errs, out.get("carry_turn_end_s", []))
    worst = max(docking, key=lambda e: e[1], default=None)
    if worst is not None:
        out["pose_error_docking_worst_at_s"] = round(worst[0], 2)
        out["pose_error_docking_worst_in"] = next(w for t0, t1, w in windows if t0 <= worst[0] <= t1)
    return out


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q / 100 * (len(v) - 1))))]
