"""``raf up``: the whole set on one machine without launch files: raf sim + bridge + localization (+ agent).

What launch/sim.launch and launch/competition.launch start (ROS 1), and launch/ros2/*.launch.py (ROS 2, on a
real Jazzy install), as child processes of this interpreter, on this process's middleware: ``raf up`` with
.venv is ROS 1, ``raf --middleware ros2 up`` is ROS 2. Each child logs to a file of its own and runs in a
process group of its own; Ctrl-C (or SIGTERM) stops them all; when one dies, the others are stopped and
its last log lines are printed (exit code 1).
"""
from __future__ import annotations

import argparse

NAME = "up"
HELP = "start raf sim + bridge + localization (+ agent, RViz) on this machine, on ROS 1 or ROS 2; Ctrl-C stops all"
ORDER = 26
DESCRIPTION = """\
Start the stand-in simulator and the ROS nodes as one set, without launch files (the same set as
launch/sim.launch, launch/competition.launch and launch/ros2/*.launch.py): raf sim, raf bridge,
raf localize and, with --agent, raf agent. It prints what runs where (pids, ports, logs), keeps running
until Ctrl-C (or until raf sim ends with --duration), then stops everything. If a child dies, the rest are
stopped and its last log lines printed (exit code 1).

The graph: ROS 2 (raf --middleware ros2 up) uses $ROS_DOMAIN_ID if set, else a private domain id of its
own (printed: export it to talk to the set). ROS 1 uses $ROS_MASTER_URI, or with --roscore a private
roscore on a free port (printed).

examples:
  raf up --roscore                           # ROS 1: sim (lockstep) + bridge + localization
  raf --middleware ros2 up                   # the same on ROS 2 Jazzy
  raf --middleware ros2 up --agent --round 2 # one robot playing round 2 (realtime), as competition.launch
  raf up --roscore --no-localize --rviz      # map -> odom from the first ground truth, RViz (ROS 1)
"""

LOG_TAIL = 25  # lines of a dead child's log printed


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..sim.control import CONTROL_PORT_OFFSET
    from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, SERVER_UDP_PORT, SIMTWO_UDP_PORT

    g = parser.add_argument_group("what runs")
    g.add_argument("--agent", action="store_true", help="also run raf agent (plays the round; raf sim then runs "
                                                        "realtime with --start-after 3, as competition.launch)")
    g.add_argument("--no-localize", action="store_true",
                   help="no localization node (the bridge then takes map -> odom from the first ground truth)")
    g.add_argument("--rviz", action="store_true", help="also start RViz (ROS 1: rviz; ROS 2: rviz2 if installed)")
    g = parser.add_argument_group("simulator")
    g.add_argument("--simulator", choices=("standin", "simtwo"), default="standin",
                   help="standin: raf sim (default); simtwo: the real SimTwo (raf simtwo run, built by raf simtwo "
                        "build), realtime, the field simtwo2022, the round's parts placed in its scene and, with "
                        "--agent, raf referee (the factory-state server, the machines and the score, from the part positions "
                        "SimTwo's script reports)")
    g.add_argument("--round", type=int, choices=(1, 2, 3), default=1, help="competition round (default 1)")
    g.add_argument("--seed", type=int, default=0, help="seed of the round and the noise (default 0)")
    mode = g.add_mutually_exclusive_group()
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="raf sim --realtime (default with --agent)")
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="raf sim --lockstep (default without --agent): each step waits for the bridge's reply")
    g.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds of simulation (raf sim --duration); default: until Ctrl-C")
    g.add_argument("--sim-arg", action="append", default=[], metavar="ARG",
                   help="one more argument for raf sim, e.g. --sim-arg=--beacons (repeatable)")
    g = parser.add_argument_group("graph, ports and logs")
    g.add_argument("--roscore", action="store_true", help="ROS 1: start a private roscore on a free port")
    g.add_argument("--free-ports", action="store_true",
                   help=f"free ports instead of the defaults {SIMTWO_UDP_PORT}/{BRIDGE_UDP_PORT}/"
                        f"{SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}/{CAMERA_ZMQ_PORT}/{SERVER_UDP_PORT} (several sets "
                        "at once)")
    g.add_argument("--log-dir", metavar="DIR", help="where each child's log goes (default: a new temporary folder)")
    g.add_argument("--ready-timeout", type=float, default=60.0, metavar="S",
                   help="how long a node may take to come up (default 60 s)")


def _ports(free: bool) -> dict:
    import socket

    from ..ros.master import free_port
    from ..sim.control import control_port_for
    from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, SERVER_UDP_PORT, SIMTWO_UDP_PORT

    if not free:
        return {"sim": SIMTWO_UDP_PORT, "bridge": BRIDGE_UDP_PORT, "control": control_port_for(SIMTWO_UDP_PORT),
                "camera": CAMERA_ZMQ_PORT, "server": SERVER_UDP_PORT}
    udp = lambda: free_port(socket.SOCK_DGRAM)  # noqa: E731
    return {"sim": udp(), "bridge": udp(), "control": udp(), "camera": free_port(), "server": udp()}


def plan(args, mw: str, ports: dict) -> list[tuple[str, list[str], str]]:
    """(name, raf arguments, the line saying where it runs) per child, in start order: the bridge first, so
    that it holds its port (a free port chosen now) before anything else can take it and listens before the
    simulator sends; raf sim last; SimTwo (10-20 s to start) before the factory server and the agent, so that
    the round starts once SimTwo streams."""
    from ..errors import ConfigError
    from ..simtwo_linux.scene import field_for_simtwo

    simtwo = args.simulator == "simtwo"
    if simtwo and args.mode == "lockstep":
        raise ConfigError("--lockstep: the real SimTwo runs in real time only (no lockstep)")
    field = ["--field", field_for_simtwo(args.field) if simtwo else args.field]
    cam = f"tcp://127.0.0.1:{ports['camera']}"
    bridge = [*field, "bridge", "--port", str(ports["bridge"]), "--camera", cam, "--sim-host", "127.0.0.1"]
    if simtwo:
        services = "via SimTwo's teleport labels"
    else:
        bridge += ["--set", f"simulator/control=127.0.0.1:{ports['control']}"]
        services = f"via 127.0.0.1:{ports['control']}"
    if args.no_localize:
        bridge += ["--set", "tf/map_to_odom=first_ground_truth"]
    nodes = [("bridge", bridge, f"udp 127.0.0.1:{ports['bridge']} <- SensorFrames, camera {cam}, sim/* services "
                                f"{services}")]
    if not args.no_localize:
        nodes.append(("localize", [*field, "localize"], "pose, camera_pose, aruco/*, map -> odom"))
    if args.agent:
        if simtwo:  # raf sim serves the round itself; with SimTwo the referee does, from SimTwo's part positions
            nodes.append(("referee", [*field, "referee", "--round", str(args.round), "--seed", str(args.seed),
                                      "--server-port", str(ports["server"]), "--start-after", "3"],
                          f"factory-state server udp 127.0.0.1:{ports['server']}, machines and score from SimTwo's "
                          "part positions"))
        nodes.append(("agent", [*field, "agent", "--server-port", str(ports["server"])],
                      f"factory-state server udp 127.0.0.1:{ports['server']}"))
    if simtwo:
        sim = [*field, "simtwo", "run", "--port", str(ports["sim"]), "--bridge", f"127.0.0.1:{ports['bridge']}",
               "--camera-port", str(ports["camera"]), "--round", str(args.round), "--seed", str(args.seed)]
        what = (f"the real SimTwo, round {args.round} seed {args.seed} parts, commands on udp 127.0.0.1:"
                f"{ports['sim']}, camera {cam}")
    else:
        mode = args.mode or ("realtime" if args.agent else "lockstep")
        sim = [*field, "sim", f"--{mode}", "--round", str(args.round), "--seed", str(args.seed),
               "--port", str(ports["sim"]), "--bridge", f"127.0.0.1:{ports['bridge']}", "--camera-bind", cam,
               "--server-port", str(ports["server"]), "--control-port", str(ports["control"])]
        if args.agent:
            sim += ["--start-after", "3"]
        what = f"{mode}, round {args.round} seed {args.seed}, commands on udp 127.0.0.1:{ports['sim']}"
    if args.duration is not None:
        sim += ["--duration", str(args.duration)]
    sim += list(args.sim_arg)
    if simtwo:
        first = [n for n in nodes if n[0] in ("bridge", "localize")]
        return [*first, ("sim", sim, what), *nodes[len(first):]]
    return [*nodes, ("sim", sim, what)]


class Children:
    """The children of one ``raf up``: each in a session of its own, output to ``log_dir/NAME.log``."""

    def __init__(self, log_dir, env: dict):
        from pathlib import Path

        self.log_dir = Path(log_dir)
        self.env = env
        self.procs: list[tuple[str, object]] = []

    def start(self, name: str, cmd: list[str]):
        import subprocess

        with open(self.log_dir / f"{name}.log", "wb") as log:
            p = subprocess.Popen(cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 start_new_session=True)
        self.procs.append((name, p))
        return p

    def log(self, name: str) -> str:
        try:
            return (self.log_dir / f"{name}.log").read_text(errors="replace")
        except OSError:
            return ""

    def tail(self, name: str, n: int = LOG_TAIL) -> str:
        return "\n".join("    " + line for line in self.log(name).splitlines()[-n:])

    def dead(self):
        """(name, exit code) of the first child that has exited, or None."""
        for name, p in self.procs:
            if p.poll() is not None:
                return name, p.returncode
        return None

    def stop_all(self, grace: float = 10.0) -> None:
        """SIGINT to every child's process group (last started first: the simulator before the nodes), also
        a group whose leader died (the bridge's camera process lives on in it); SIGKILL to what is left of
        any group after ``grace`` s."""
        import os
        import signal
        import time

        def alive(pgid: int) -> bool:
            try:
                os.killpg(pgid, 0)
                return True
            except (ProcessLookupError, PermissionError):
                return False

        groups = [p.pid for _, p in reversed(self.procs)]
        for pgid in groups:
            try:
                os.killpg(pgid, signal.SIGINT)
            except ProcessLookupError:
                pass
        end = time.monotonic() + grace
        while time.monotonic() < end:
            for _, p in self.procs:
                p.poll()  # reap the leaders, so that their groups can empty
            if not any(alive(g) for g in groups):
                break
            time.sleep(0.05)
        for pgid in groups:
            if alive(pgid):
                try:
                    os.killpg(pgid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        for _, p in self.procs:
            try:
                p.wait(5)
            except Exception:  # noqa: BLE001 - a process in uninterruptible sleep: reported by the caller
                pass


def _wait_ready(children: "Children", name: str, marker: str, timeout: float, interrupted) -> None:
    """Until ``name``'s log has ``marker`` (the command's "running" line). Raises _ChildDied when a child dies,
    KeyboardInterrupt when ``interrupted()``, RuntimeError (with the log's tail) after ``timeout`` s."""
    import time

    end = time.monotonic() + timeout
    while marker not in children.log(name):
        d = children.dead()
        if d is not None:
            raise _ChildDied(*d)
        if interrupted():
            raise KeyboardInterrupt
        if time.monotonic() > end:
            raise RuntimeError(f"{name} did not come up within {timeout:.0f} s; its log:\n{children.tail(name)}")
        time.sleep(0.1)


class _ChildDied(Exception):
    def __init__(self, name: str, code: int):
        super().__init__(name, code)
        self.name, self.code = name, code


#: the line each command prints once it runs (ros/cli.run_node's "raf WHO: ..." line, raf sim's banner)
READY = {"bridge": " listening on udp ", "localize": " running (field ", "agent": " running (field ",
         "sim": "raf sim: field ", "simtwo": "[simtwo] running (", "server": "factory-state server on udp ",
         "referee": " running (field "}


def _graph(args, mw: str):
    """Start the graph this set runs in; returns (env for the children, the graph object to clean up, text)."""
    import os

    from ..errors import ConfigError
    from ..ros import mw as mwmod
    from ..ros.master import PrivateDomain, PrivateMaster

    if not mwmod.has_master(mw):  # ROS 2: a domain id of its own
        if args.roscore:
            raise ConfigError("--roscore is for ROS 1; ROS 2 has no master (a private ROS_DOMAIN_ID is used "
                              "unless ROS_DOMAIN_ID is set)")
        if os.environ.get("ROS_DOMAIN_ID", "").strip():
            env = dict(os.environ, RAF_MIDDLEWARE=mw, PYTHONUNBUFFERED="1")
            env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
            return env, None, (f"ROS 2, ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} (from the environment), discovery "
                               f"{env['ROS_AUTOMATIC_DISCOVERY_RANGE']}")
        dom = PrivateDomain().start()
        return dom.env(), dom, (f"ROS 2, private ROS_DOMAIN_ID={dom.domain_id} (to join: export ROS_DOMAIN_ID="
                                f"{dom.domain_id} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)")
    if args.roscore:
        m = PrivateMaster().start()
        return m.env(), m, f"ROS 1, private roscore {m.uri} (to join: export ROS_MASTER_URI={m.uri})"
    uri = mwmod.api().require_master("start roscore, or pass --roscore")
    env = dict(os.environ, RAF_MIDDLEWARE=mw, PYTHONUNBUFFERED="1")
    return env, None, f"ROS 1, roscore {uri}"


def _rviz_cmd(mw: str) -> list[str]:
    import shutil

    from ..errors import ConfigError
    from ..ros.master import ROOT

    if mw == "ros1":
        if not shutil.which("rviz"):
            raise ConfigError("--rviz: rviz is not installed (Debian: apt install rviz)")
        return ["rviz", "-d", str(ROOT / "rviz" / "robotatfactory.rviz")]
    if not shutil.which("rviz2"):
        raise ConfigError("--rviz: rviz2 is not installed (PyPI has no rviz2 wheel: use a real ROS 2 install, or "
                          "RViz on ROS 1 through raf up --roscore --rviz)")
    return ["rviz2", "-f", "map"]


def run(args) -> int:
    import signal
    import sys
    import tempfile
    import time
    from pathlib import Path

    from ..errors import ConfigError
    from ..ros import mw as mwmod

    mw = mwmod.name()
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(f"--duration must be > 0 s, got {args.duration}")
    rviz = _rviz_cmd(mw) if args.rviz else None
    ports = _ports(args.free_ports)
    env, graph, where = _graph(args, mw)
    log_dir = Path(args.log_dir) if args.log_dir else Path(tempfile.mkdtemp(prefix="raf-up-"))
    log_dir.mkdir(parents=True, exist_ok=True)
    children = Children(log_dir, env)
    raf = [sys.executable, "-m", "robotatfactory"]

    stopping = {"signal": None}

    def on_signal(signum, _frame):
        stopping["signal"] = signum

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    code = 0
    try:
        print(f"raf up: {where}; logs in {log_dir}", flush=True)
        for name, argv, what in plan(args, mw, ports):
            p = children.start(name, raf + argv)
            print(f"  {name:<9} pid {p.pid:<7} {what}", flush=True)
            marker = READY["simtwo" if name == "sim" and args.simulator == "simtwo" else name]
            _wait_ready(children, name, marker, args.ready_timeout, lambda: stopping["signal"] is not None)
        if rviz:
            p = children.start("rviz", rviz)
            print(f"  {'rviz':<9} pid {p.pid:<7} {' '.join(rviz)}", flush=True)
        print("raf up: running" + (f" for {args.duration:g} s of simulation" if args.duration else "")
              + "; Ctrl-C stops everything", flush=True)
        while stopping["signal"] is None:
            d = children.dead()
            if d is not None:
                name, rc = d
                if name == "sim" and rc == 0:
                    print(f"raf up: {'SimTwo' if args.simulator == 'simtwo' else 'raf sim'} ended; stopping the rest",
                          flush=True)
                    break
                raise _ChildDied(name, rc)
            time.sleep(0.2)
        else:
            print(f"raf up: {signal.Signals(stopping['signal']).name}: stopping everything", flush=True)
    except _ChildDied as e:
        print(f"raf up: {e.name} exited with code {e.code}; stopping the rest. Last lines of {log_dir / (e.name + '.log')}:"
              f"\n{children.tail(e.name)}", file=sys.stderr, flush=True)
        code = 1
    except KeyboardInterrupt:
        print("raf up: interrupted: stopping everything", flush=True)
    except RuntimeError as e:
        print(f"raf up: {e}", file=sys.stderr, flush=True)
        code = 1
    finally:
        children.stop_all()
        if graph is not None:
            graph.cleanup()
        for s, h in old.items():
            signal.signal(s, h)
    left = [n for n, p in children.procs if p.poll() is None]
    print(f"raf up: stopped ({len(children.procs)} processes" + (f"; still running: {left}" if left else "") + ")",
          flush=True)
    return code
