"""``raf simtwo``: the real SimTwo on Linux: build it from pinned sources, run it headless.

``build`` and ``run`` are thin over :mod:`robotatfactory.simtwo_linux` (no ROS).
"""
from __future__ import annotations

import argparse

from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SIMTWO_UDP_PORT

NAME = "simtwo"
HELP = "the real SimTwo on Linux: build it from pinned sources (build), run it headless (run)"
ORDER = 21
DESCRIPTION = f"""\
SimTwo, the competition's simulator, built from pinned sources with the project's Linux patches
(simtwo/linux/) and run headless under its own Xvfb, with the project's control.pas, LIDAR and settings
installed into a fresh copy of the scene (docs/simtwo.md, "SimTwo on Linux").

  raf simtwo build --sources ../shared/vendor/simtwo    build (cached under build/simtwo/: a second run
                                                       with nothing changed takes under a second)
  raf simtwo build                                     the same; the sources from $RAF_SIMTWO_SOURCES, else
                                                       ../shared/vendor/simtwo beside the repository, else
                                                       git clones at the pinned commits
  raf simtwo run                                       RobotFactoryPro2022 on the default ports (UDP {SIMTWO_UDP_PORT} in,
                                                       frames to {LOCALHOST}:{BRIDGE_UDP_PORT}, camera tcp {CAMERA_ZMQ_PORT}) until Ctrl-C
  raf simtwo run --free-ports                          free ports (printed), for a run beside others
  raf simtwo run --robot robot.json                    the scene's camera set to the robot file's (fx = fy,
                                                       centred principal point, pitch, mount)
  raf simtwo info                                      where the build is, its patches, the tools
  raf simtwo field                                     what SimTwo built (walls, markers, slots, start pose,
                                                       read back from SimTwo) against the simtwo2022 field

Then: raf --field simtwo2022 bridge (the same ports), or raf up --simulator simtwo for the whole stack."""


ROBOT_HELP = ("a robot file (the JSON raf sim --robot takes) whose camera the scene's AGV.xml gets: focal length "
              "from fx at 96 dpi, pitch, mount height and forward offset; refused when GLScene cannot render it "
              "(fx != fy, principal point off the centre, distortion, roll). Only the camera: SimTwo's wheels, "
              "motors and LIDAR stay the scene's")


def robot_camera(path: str | None):
    """The camera of robot file ``path`` checked for SimTwo's scene (None without a file); ConfigError says
    what GLScene cannot render."""
    if not path:
        return None
    from ..errors import ConfigError
    from ..robot import load_robot
    from ..simtwo_linux.scene import camera_refusals

    try:
        cam = load_robot(path).camera
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"--robot {path}: {e}") from None
    why = camera_refusals(cam)
    if why:
        raise ConfigError(f"--robot {path}: SimTwo's camera cannot render it: " + "; ".join(why))
    return cam


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    b = sub.add_parser("build", help="build SimTwo from the pinned sources (cached)",
                       description="Build SimTwo: Debian's packages checked, the pinned sources (an archive "
                                   "directory or git), the project's patches, lazbuild with a private "
                                   "configuration. Output: build/simtwo/<key>/.")
    b.add_argument("--sources", metavar="DIR", help="a directory with the pinned archives (simtwo/linux/"
                                                    "sources.json), e.g. ../shared/vendor/simtwo")
    b.add_argument("--force", action="store_true", help="build again even when a build of these inputs exists")
    r = sub.add_parser("run", help="run SimTwo headless until Ctrl-C (or --duration)",
                       description="Start SimTwo headless: a fresh copy of the scene with the project's side "
                                   "installed, its own Xvfb and ports, the camera window opened; wait until the "
                                   "script streams; run until Ctrl-C or --duration; stop all it started.")
    r.add_argument("--scene", default="RobotFactoryPro2022", help="the scene folder (default RobotFactoryPro2022)")
    r.add_argument("--port", type=int, metavar="UDP",
                   help=f"the UDP port SimTwo listens on (default {SIMTWO_UDP_PORT})")
    r.add_argument("--bridge", default=None, metavar="HOST:PORT",
                   help=f"where the SensorFrames go (control.pas BRIDGE_IP/BRIDGE_PORT; default "
                        f"{LOCALHOST}:{BRIDGE_UDP_PORT})")
    r.add_argument("--camera-port", type=int, metavar="TCP", help=f"the camera's ZMQ port (default {CAMERA_ZMQ_PORT})")
    r.add_argument("--free-ports", action="store_true", help="free ports for all three (printed)")
    r.add_argument("--no-camera", action="store_true", help="do not open SimTwo's camera window")
    r.add_argument("--round", type=int, choices=(1, 2, 3),
                   help="put the scene's parts (Part1..Part4) on the incoming slots as this round's draw has them "
                        "(with --seed or --parts; default: where SimTwo's scene file has them)")
    r.add_argument("--seed", type=int, default=0, help="seed of the round's draw (default 0)")
    r.add_argument("--parts", metavar="RGBX", help="the incoming parts, slot 1 first (overrides the draw)")
    r.add_argument("--script", metavar="FILE", help="another scene script instead of simtwo/control.pas")
    r.add_argument("--robot", metavar="FILE", help=ROBOT_HELP)
    r.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: until Ctrl-C)")
    r.add_argument("--ready-timeout", type=float, default=90.0, metavar="S",
                   help="how long SimTwo may take until its script streams (default 90)")
    r.add_argument("--ready-line", default="raf: streaming to", metavar="TEXT",
                   help="the start of the line the script prints (WriteLn) when it runs (default: control.pas's "
                        "'raf: streaming to', printed right before its first SensorFrame)")
    r.add_argument("--keep", metavar="DIR", help="run in DIR, a new or empty folder, and keep it (the scene copy, "
                                                 "simtwo.log, xvfb.log)")
    sub.add_parser("info", help="the build's folder, patches and tools")
    f = sub.add_parser("field", help="what SimTwo built against the field model (one SimTwo start)",
                       description="Run simtwo/linux/field_dump.pas in SimTwo's scene: every obstacle SimTwo built, "
                                   "the robots' start poses, a part set down at each slot, LIDAR sweeps and camera "
                                   "frames in front of the warehouses and machines; compare them with the field "
                                   "model (simtwo2022 unless --field names another) and list each difference "
                                   "with its size. Exit 1 when there are differences beyond the tolerances.")
    f.add_argument("--keep", metavar="DIR", help="run in DIR, a new or empty folder, and keep it")
    f.add_argument("--robot", metavar="FILE", help=ROBOT_HELP + "; the camera frames are compared with its "
                                                                "projection")


def _progress(msg: str) -> None:
    print(f"[simtwo] {msg}", flush=True)


def run(args) -> int:
    from ..simtwo_linux import build as b

    if args.action == "build":
        from pathlib import Path

        sources = Path(args.sources) if args.sources else b.default_sources()
        try:
            res = b.build(sources, progress=_progress, force=args.force)
        except b.BuildError as e:
            print(f"raf simtwo build: {e}", flush=True)
            return 1
        what = "up to date" if res.cached else "built"
        _progress(f"{what}: {res.executable} ({res.seconds:.1f} s)")
        return 0
    if args.action == "info":
        found = b.find()
        print(f"build:   {found.executable if found else 'not built (raf simtwo build)'}")
        print(f"key:     {b.cache_key()} (build/simtwo/<key>)")
        print(f"tools:   {b.tool_versions()}")
        print(f"sources: {b.default_sources() or 'git clones'}")
        missing = b.missing_packages()
        print(f"Debian:  {'all installed' if not missing else 'missing ' + ' '.join(missing)}")
        for p in b.patches():
            print(f"patch:   {p.parent.name}/{p.name}")
        return 0
    if args.action == "field":
        return _field(args, b)
    return _run(args, b)


def _field(args, b) -> int:
    from pathlib import Path

    from ..field import load_field
    from ..simtwo_linux import fielddump
    from ..simtwo_linux.run import SimTwoError
    from ..simtwo_linux.scene import field_for_simtwo

    cam = robot_camera(args.robot)  # refused before anything starts
    build = b.require()
    fld = load_field(field_for_simtwo(args.field))
    try:
        dump = fielddump.run_dump(fld, build, keep=Path(args.keep) if args.keep else None, progress=_progress,
                                  robot_camera=cam)
    except (SimTwoError, TimeoutError) as e:
        print(f"raf simtwo field: {e}", flush=True)
        return 1
    robot = None
    if args.robot:
        from ..robot import load_robot

        robot = load_robot(args.robot)
    rep = fielddump.compare(dump, fld, fielddump.scene_dir(build), robot=robot)
    print(f"field {fld.name} against SimTwo's {fielddump.DEFAULT_SCENE}:")
    print(fielddump.format_report(rep), flush=True)
    return 1 if rep.differences else 0


def _sigterm(_sig, _frame):
    raise SystemExit(143)  # stop() runs in the finally, as on Ctrl-C


def _run(args, b) -> int:
    import signal
    import time
    from pathlib import Path

    from ..errors import ConfigError
    from ..simtwo_linux.run import Ports, SimTwoError, SimTwoRun

    cam = robot_camera(args.robot)  # refused before anything starts
    build = b.require()  # a BuildError (a user error: raf prints it) when it is not built
    ports = Ports.free() if args.free_ports else Ports()
    host = "127.0.0.1"
    if args.port:
        ports.udp = args.port
    if args.camera_port:
        ports.camera = args.camera_port
    if args.bridge:
        host, _, port = args.bridge.rpartition(":")
        if not host or not port.isdigit():
            raise ConfigError(f"--bridge {args.bridge}: expected HOST:PORT")
        ports.bridge = int(port)
    parts = None
    if args.round is not None:
        from ..competition.rounds import RoundSetup
        from ..field import load_field
        from ..simtwo_linux.scene import field_for_simtwo, round_parts

        setup = RoundSetup.make(args.round, args.seed, args.parts)
        parts = round_parts(load_field(field_for_simtwo(args.field)), setup.incoming)
        _progress(setup.describe())
    elif args.parts or args.seed:
        raise ConfigError("--parts and --seed place a round's parts: give --round too")
    workdir = Path(args.keep) if args.keep else None
    if workdir is not None and workdir.exists() and (not workdir.is_dir() or any(workdir.iterdir())):
        raise ConfigError(f"--keep {workdir}: not a new or empty folder (the run writes its scene copy and logs "
                          "there and keeps them)")
    sim = SimTwoRun(build, ports, scene=args.scene, parts=parts, ready_line=f"script: {args.ready_line}",
                    camera=not args.no_camera, bridge_host=host, script=Path(args.script) if args.script else None,
                    workdir=workdir, keep=workdir is not None, progress=_progress, robot_camera=cam)
    signal.signal(signal.SIGTERM, _sigterm)
    try:
        sim.start(args.ready_timeout)
        _progress(f"running (pid {sim.pid}, display {sim.display}): udp {ports.udp}, frames to {host}:"
                  f"{ports.bridge}, camera tcp://127.0.0.1:{ports.camera}; Ctrl-C stops it")
        end = time.monotonic() + args.duration if args.duration else None
        while end is None or time.monotonic() < end:
            sim.check()
            time.sleep(0.2)
        return 0
    except SimTwoError as e:
        print(f"raf simtwo run: {e}", flush=True)
        return 1
    finally:
        sim.stop()
        if args.keep:
            _progress(f"kept {args.keep}")
