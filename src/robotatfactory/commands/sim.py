"""``raf sim``: the stand-in simulator (MuJoCo) speaking SimTwo's protocol, with the competition inside."""
from __future__ import annotations

import argparse

from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SERVER_UDP_PORT, SIMTWO_UDP_PORT
from ..sim.config import (CAMERA_TIMINGS, LIDAR_UPDATES, MAGNETS, PID_TIMINGS, REPLY_TIMINGS, SPEED_CONTROLS,
                          SimConfig)
from ..sim.control import CONTROL_PORT_OFFSET
from ..sim.multirunner import PORT_STRIDE
from ..sim.runner import RunnerConfig

NAME = "sim"
HELP = "run the stand-in simulator: MuJoCo physics, SimTwo's UDP/ZMQ protocol, the competition and its server"
ORDER = 20
_ROBOT2 = "/".join(str(p + PORT_STRIDE) for p in (SIMTWO_UDP_PORT, BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT))
DESCRIPTION = f"""\
The RobotAtFactory 4.0 scene in MuJoCo, talking to the outside world as SimTwo does: one SensorFrame
datagram per 40 ms control cycle to the bridge, Commands received on --port, camera frames on a ZMQ PUB
socket (raw B G R A, bottom-up, about 15 frames/s, rendered when SimTwo's GUI loop would render them:
--camera-timing), the factory-state server on UDP {SERVER_UDP_PORT}.

examples:
  raf sim                                  # real time, round 1, camera and server on
  raf sim --fast --no-camera --duration 60 # as fast as possible, one simulated minute
  raf sim --lockstep --on-timeout stop     # wait for the controller's reply every cycle
  raf sim --paced                          # wait for each reply, apply it a cycle later (real time's latency)
  raf sim --round 3 --parts RGBX --seed 4  # round 3 with a given layout
  raf sim --snapshot field.png             # an overview picture, then exit
  raf sim --robots 2                       # two robots: robot 2 on ports {_ROBOT2} (+{PORT_STRIDE} per robot)
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("endpoints")
    g.add_argument("--host", default=LOCALHOST, help=f"address to receive commands on (default {LOCALHOST})")
    g.add_argument("--port", type=int, default=SIMTWO_UDP_PORT,
                   help=f"UDP port to receive commands on (default {SIMTWO_UDP_PORT})")
    g.add_argument("--bridge", default=f"{LOCALHOST}:{BRIDGE_UDP_PORT}", metavar="HOST:PORT",
                   help=f"where sensor frames go (default {LOCALHOST}:{BRIDGE_UDP_PORT})")
    cam = g.add_mutually_exclusive_group()
    cam.add_argument("--camera-bind", default=f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}", metavar="ENDPOINT",
                     help=f"ZMQ PUB endpoint of the camera (default tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT})")
    cam.add_argument("--no-camera", action="store_true", help="do not render or publish camera frames")
    g.add_argument("--camera-timing", choices=CAMERA_TIMINGS,
                   help="when camera frames are rendered: simtwo (default: as SimTwo's GUI loop, at the ends of "
                        "17 ms physics chunks chosen by a wall clock, not a grid of simulation time) or grid "
                        "(the idealisation: every 1/15 s of simulation time); docs/simulator.md")
    g.add_argument("--reply-timing", choices=REPLY_TIMINGS,
                   help="free-running: when the controller's replies are read: simtwo (default: only at the first "
                        "script call of each GUI turn of that same loop, and of several replies read at once the "
                        "first is applied, as SimTwo's ReadUDPData) or every_cycle (the idealisation: the newest "
                        "reply before every cycle); docs/simulator.md")
    srv = g.add_mutually_exclusive_group()
    srv.add_argument("--server-port", type=int, default=SERVER_UDP_PORT,
                     help=f"UDP port of the factory-state server (default {SERVER_UDP_PORT}, on --host)")
    srv.add_argument("--no-server", action="store_true", help="no factory-state server")

    ctl = g.add_mutually_exclusive_group()
    ctl.add_argument("--control-port", type=int, default=None, metavar="PORT",
                     help="UDP port of the control channel (reset, pause, resume, step, set_robot_pose, "
                          "place_part, remove_part, get_state: JSON requests, docs/protocol.md) on --host "
                          f"(default: --port + {CONTROL_PORT_OFFSET}, i.e. {SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}; when "
                          "that one is taken, a warning and no channel)")
    ctl.add_argument("--no-control", action="store_true", help="no control channel")
    g.add_argument("--controller", default=None, metavar="HOST:PORT",
                   help="accept commands from this source only (default: the first that sends a valid command; "
                        "another takes over after it has been silent for --takeover-after seconds)")
    g.add_argument("--takeover-after", type=float, default=RunnerConfig.takeover_after, metavar="S",
                   help="wall seconds the controller must be silent before another source may take over "
                        f"(default {RunnerConfig.takeover_after:g})")

    g = p.add_argument_group("timing")
    mode = g.add_mutually_exclusive_group()
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="pace simulation time to the wall clock (default)")
    mode.add_argument("--fast", dest="mode", action="store_const", const="fast", help="run as fast as possible")
    mode.add_argument("--paced", dest="mode", action="store_const", const="paced",
                      help="as fast as the controller answers: wait for the reply to each frame (up to "
                           "--lockstep-timeout, then --on-timeout) and apply it in the next cycle, where a "
                           "free-running run reads it: real time's loop latency without the wall clock")
    p.set_defaults(mode="realtime")
    g.add_argument("--paused", action="store_true",
                   help="start paused: the control channel's step and resume requests run it")
    g.add_argument("--lockstep", action="store_true",
                   help="wait each cycle for the controller's reply to the frame just sent")
    g.add_argument("--pace-hold", type=int, default=RunnerConfig.pace_hold, metavar="N",
                   help="--paced: script calls a reply waits before it is applied (default "
                        f"{RunnerConfig.pace_hold}: as free-running, for a controller that replies at once; 2 for "
                        "one that answers each frame with its decision on that frame, as the paced whole stack)")
    g.add_argument("--lockstep-timeout", type=float, default=RunnerConfig.lockstep_timeout, metavar="S",
                   help=f"wall seconds to wait for a reply in lockstep or --paced (default "
                        f"{RunnerConfig.lockstep_timeout:g})")
    g.add_argument("--on-timeout", choices=("stop", "hold", "exit"), default=RunnerConfig.on_timeout,
                   help="when no reply comes in time: stop the robot (V=W=0, magnet kept), hold the last "
                        "command, or exit (code 3); always with a warning (default stop)")
    g.add_argument("--command-timeout", type=float, default=RunnerConfig.command_timeout, metavar="S",
                   help="simulation seconds without a valid command before the robot stops, as SimTwo's "
                        f"control.pas does (default {RunnerConfig.command_timeout:g}; 0: keep the last command "
                        "forever)")
    g.add_argument("--duration", type=float, default=None, metavar="S",
                   help="simulation seconds to run, then print the score and exit (default: until Ctrl-C)")

    g = p.add_argument_group("scene and competition (the simulator's settings: sim/config.py SimConfig)")
    g.add_argument("--config", metavar="FILE", help="YAML of SimConfig settings, e.g. 'magnet: weld' (the options "
                                                     "below and --set go over it)")
    g.add_argument("--set", metavar="NAME=VALUE", action="append", default=[],
                   help="set one SimConfig setting, e.g. lidar_update=per_ray (repeatable; last)")
    g.add_argument("--seed", type=int, help=f"seed of the round draw and the sensor noise (default {SimConfig.seed})")
    g.add_argument("--round", type=int, choices=(1, 2, 3), dest="round_no",
                   help=f"round (default {SimConfig.round_no})")
    g.add_argument("--parts", default=None, metavar="RGBX",
                   help="incoming warehouse layout, slot 1 first (R, G, B or X for empty) instead of the draw")
    g.add_argument("--processing-delay", type=float, metavar="S",
                   help=f"machine processing time in simulation seconds (default {SimConfig.processing_delay:g})")
    g.add_argument("--start-after", type=float, metavar="S",
                   help="simulation seconds before the run starts; the server says STOP until then (default "
                        f"{SimConfig.start_after:g})")
    g.add_argument("--robots", type=int, default=SimConfig.robots, metavar="N",
                   help="robots in the scene, 1..4 (default 1). Robot k's command, bridge and camera ports are "
                        f"robot 1's + {PORT_STRIDE}*(k-1) (printed at start); one factory server sees them all; "
                        "no control "
                        "channel with several robots; start poses: the start area's 2x2 cells or --start-pose")
    g.add_argument("--start-pose", default=None, action="append", metavar="X,Y,THETA",
                   help="robot start pose in metres and radians (default: the field's start pose); with --robots "
                        "N: once per robot, in order, or one list X,Y,THETA;X,Y,THETA;...")
    g.add_argument("--beacons", action="store_true", help="put the LIDAR beacons in the team areas")
    g.add_argument("--robot", default="simtwo", help="robot parameters: shipped name or a .json file (default simtwo)")

    g = p.add_argument_group("SimTwo fidelity (defaults behave like SimTwo; the rest are idealisations, "
                             "docs/simulator.md)")
    g.add_argument("--lidar-update", choices=LIDAR_UPDATES,
                   help="sweep: all rays published at once once per period, 0 before the first (SimTwo); per_ray: "
                        "each ray as soon as measured (default sweep)")
    g.add_argument("--no-lidar-self-hits", action="store_true",
                   help="let the LIDAR's rays pass through the robot's own wheels (SimTwo's hit them)")
    g.add_argument("--speed-control", choices=SPEED_CONTROLS,
                   help="simtwo: SimTwo's CalcPID set once (default); simtwo_per_cycle: its integral reset every "
                        "cycle (SetMotorControllerState each cycle); ideal_pi: the stand-in's own 1 ms PI")
    g.add_argument("--pid-timing", choices=PID_TIMINGS,
                   help="when SimTwo's PID runs against the script calls: script_enabled (0 V for 9 ms after each "
                        "call, default), scene_enabled or script_holds_voltage (no gap)")
    g.add_argument("--magnet", choices=MAGNETS,
                   help="force: SimTwo's electromagnet, a 5 N pull along one 2 cm ray while it meets a part's plate, "
                        "every physics step: a part can hang askew, slip off or be lost (default); weld: the "
                        "idealisation, a facing plate is welded flat to the magnet and never lost")

    g = p.add_argument_group("output")
    g.add_argument("--status-every", type=float, default=RunnerConfig.status_every, metavar="S",
                   help=f"print a status line every S wall seconds (default {RunnerConfig.status_every:g}; 0 = "
                        "never)")
    g.add_argument("--quiet", action="store_true", help="no status lines (warnings and the final score still)")
    g.add_argument("--trace", default=None, metavar="FILE.jsonl",
                   help="write the ground truth cycle by cycle (robot pose, parts, held part, command, contact, "
                        "encoders) as JSON Lines for measuring afterwards (sim/trace.py); never sent to the robot")
    g.add_argument("--end-after-max", type=float, default=None, metavar="S",
                   help="end the run S simulated seconds after it reached the round's maximum score (the final "
                        "report as at --duration); default: run on")
    g.add_argument("--snapshot", default=None, metavar="FILE.png", help="render an overview of the scene and exit")
    g.add_argument("--snapshot-camera", choices=("overview", "top", "robot_camera"), default="overview",
                   help="the view --snapshot renders (default overview)")


def run(args) -> int:
    import logging
    import signal
    import sys

    from ..errors import ConfigError
    from ..field import load_field
    from ..robot import load_robot
    from ..sim import parse_pose
    from ..sim.config import sim_config
    from ..sim.control import control_port_for
    from ..sim.runner import RunnerConfig, parse_address

    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="raf sim: %(levelname)s: %(message)s", stream=sys.stderr)
        logging.getLogger("OpenGL").setLevel(logging.WARNING)
    field = load_field(args.field)
    robot = load_robot(args.robot)
    poses = [parse_pose(t) for text in (args.start_pose or []) for t in text.split(";") if t.strip()]
    n = args.robots
    if not 1 <= n <= 4:
        raise ConfigError(f"--robots {n}: must be 1..4")
    if n > 1 and (args.trace or args.end_after_max is not None):
        raise ConfigError("--trace and --end-after-max run with one robot only")
    if n == 1:
        if len(poses) > 1:
            raise ConfigError(f"{len(poses)} start poses for one robot (use --robots N for several)")
        start_pose, start_poses = (poses[0] if poses else None), None
    else:
        if poses and len(poses) != n:
            raise ConfigError(f"{len(poses)} start poses for {n} robots: give one per robot, or none")
        start_pose, start_poses = None, (tuple(poses) if poses else None)
        if args.control_port is not None or args.paused:
            raise ConfigError("--control-port and --paused need the control channel, which runs with one robot only")
    snapshot = args.snapshot is not None
    config = sim_config(sim_settings(args, start_pose, start_poses, snapshot))
    if config.robots != n:
        raise ConfigError(f"robots {config.robots}: give the number of robots with --robots (ports follow it)")
    if args.status_every < 0:
        raise ConfigError(f"--status-every {args.status_every}: must be >= 0")

    from ..sim import Simulator

    if snapshot:
        size = (1280, 960)
        sim = Simulator(field, robot, config, offscreen=size)
        try:
            if args.snapshot_camera == "robot_camera":
                import cv2

                cv2.imwrite(args.snapshot, sim.render_camera())
            else:
                sim.snapshot(args.snapshot, *size, camera=args.snapshot_camera)
        finally:
            sim.close()
        print(f"wrote {args.snapshot} ({args.snapshot_camera} view, field {field.name}, "
              f"{len(sim.parts.ids)} parts, round {config.round_no})")
        return 0

    runner_config = RunnerConfig(
        host=args.host, port=args.port, bridge=parse_address(args.bridge),
        camera_bind=None if args.no_camera else args.camera_bind,
        server_host=args.host, server_port=None if args.no_server else args.server_port,
        mode=args.mode, lockstep=args.lockstep, lockstep_timeout=args.lockstep_timeout, pace_hold=args.pace_hold,
        on_timeout=args.on_timeout, duration=args.duration, status_every=args.status_every, quiet=args.quiet,
        controller=parse_address(args.controller) if args.controller else None, takeover_after=args.takeover_after,
        command_timeout=args.command_timeout or None,
        control_port=None if args.no_control or n > 1 else (args.control_port if args.control_port is not None
                                                             else control_port_for(args.port)),
        start_paused=args.paused, control_optional=args.control_port is None,
        trace=args.trace, end_after_max=args.end_after_max)
    from ..sim.runner import SimRunner

    sim = Simulator(field, robot, config)
    if n > 1:
        return _run_several(field, sim, runner_config)
    runner = SimRunner(sim, runner_config)
    old = {s: signal.signal(s, runner.request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        runner.open()
        c = runner_config
        host, port = runner.address
        extras = []
        if runner.control_address is not None:
            extras.append("control udp %s:%d%s" % (*runner.control_address, " (paused)" if c.start_paused else ""))
        if c.camera_bind:
            extras.append(f"camera {c.camera_bind}")
        if runner.server is not None:
            extras.append("factory server udp %s:%d" % runner.server.address)
        if sim.setup is not None:
            extras.append(sim.setup.describe())
        extras.append(f"magnet {sim.config.magnet}")  # force (SimTwo's) or weld (the idealisation)
        print(f"raf sim: field {field.name}, commands on udp {host}:{port}, frames to udp {c.bridge[0]}:{c.bridge[1]}, "
              f"{c.mode}{' lockstep' if c.lockstep else ''}; " + "; ".join(extras), flush=True)
        if sim.world is not None:  # a world that is not the map (sim/perturb.py): sizes and this run's draw
            import json

            print(f"raf sim: world perturbed: {sim.config.perturb.describe()}; offsets "
                  f"{json.dumps(sim.world.offsets(sim.nominal_field, sim.nominal_robot, sim.config.start_pose))}",
                  flush=True)
        result = runner.run()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        runner.close()
        sim.close()
    cnt = result.counters
    print(f"raf sim: {result.reason} at t = {result.sim_time:.2f} s of simulation in {result.wall_time:.2f} s "
          f"(real-time factor {result.real_time_factor:.2f}); frames sent {cnt['frames_sent']}, commands "
          f"{cnt['commands']} (rejected {cnt['rejected']}: malformed {cnt['malformed']}, foreign "
          f"{cnt['foreign']}, version {cnt['version']}, other sources {cnt['foreign_source']}), lockstep timeouts "
          f"{cnt['timeouts']}, camera frames "
          f"{cnt['camera_frames']}", flush=True)
    if result.report is not None:
        print(result.report, flush=True)
    return result.exit_code


def sim_settings(args, start_pose=None, start_poses=None, snapshot: bool = False) -> dict:
    """The simulator's settings (SimConfig) the command line gives, as a nested tree: ``--config``, then the
    options (an option not given leaves the setting alone), then ``--set``."""
    from ..settings import deep_update, parse_set, read_yaml

    tree: dict = read_yaml(args.config, "--config") if args.config else {}
    given = {"seed": args.seed, "round_no": args.round_no, "parts": args.parts,
             "processing_delay": args.processing_delay, "start_after": args.start_after,
             "camera_timing": args.camera_timing, "reply_timing": args.reply_timing,
             "lidar_update": args.lidar_update, "speed_control": args.speed_control,
             "simtwo_pid_timing": args.pid_timing, "magnet": args.magnet,
             "start_pose": list(start_pose) if start_pose else None,
             "start_poses": [list(p) for p in start_poses] if start_poses else None}
    deep_update(tree, {k: v for k, v in given.items() if v is not None})
    if args.robots != 1:
        tree["robots"] = args.robots
    if args.beacons:
        tree["beacons"] = True
    if args.no_lidar_self_hits:
        tree["lidar_self_hits"] = False
    if args.no_camera or snapshot:
        tree["camera"] = False
    deep_update(tree, parse_set(args.set))
    return tree


def _run_several(field, sim, runner_config) -> int:
    """``raf sim --robots N`` (N >= 2): sim/multirunner.py's MultiRunner, the ports printed per robot."""
    import signal

    from ..sim.multirunner import MultiRunner

    try:
        runner = MultiRunner(sim, runner_config)
    except Exception:
        sim.close()
        raise
    old = {s: signal.signal(s, runner.request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        runner.open()
        c = runner_config
        extras = ["no control channel (several robots)"]
        if runner.server is not None:
            extras.append("factory server udp %s:%d (sees every robot)" % runner.server.address)
        if sim.setup is not None:
            extras.append(sim.setup.describe())
        extras.append(f"magnet {sim.config.magnet}")  # force (SimTwo's) or weld (the idealisation)
        print(f"raf sim: field {field.name}, {len(sim.units)} robots, {c.mode}{' lockstep' if c.lockstep else ''}; "
              + "; ".join(extras), flush=True)
        for line in runner.describe():
            print(f"raf sim: {line}", flush=True)
        results = runner.run()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        runner.close()
        sim.close()
    r0 = results[0]
    print(f"raf sim: {r0.reason} at t = {r0.sim_time:.2f} s of simulation in {r0.wall_time:.2f} s "
          f"(real-time factor {r0.real_time_factor:.2f})", flush=True)
    for k, r in enumerate(results, 1):
        cnt = r.counters
        print(f"raf sim: robot {k}: frames sent {cnt['frames_sent']}, commands {cnt['commands']} (rejected "
              f"{cnt['rejected']}), lockstep timeouts {cnt['timeouts']}, camera frames {cnt['camera_frames']}",
              flush=True)
    if r0.report is not None:
        print(r0.report, flush=True)
    return max(r.exit_code for r in results)
