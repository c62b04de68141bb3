"""``raf bridge``: run the ROS bridge node (SimTwo or ``raf sim`` <-> ROS topics and TF)."""
from __future__ import annotations

import argparse

from ..sim.multirunner import PORT_STRIDE
from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST

NAME = "bridge"
HELP = "run the ROS bridge: SimTwo's UDP/ZMQ streams as ROS topics and TF, cmd_vel back (needs a roscore)"
ORDER = 30
_ROBOT2 = f"--port {BRIDGE_UDP_PORT + PORT_STRIDE} --camera tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT + PORT_STRIDE}"
DESCRIPTION = f"""\
Run the bridge node. Settings are ROS parameters (defaults: config/bridge.yaml, every one listed in
docs/bridge.md); --config FILE overrides them from a YAML file of the same shape, --set NAME=VALUE one by
one (e.g. --set camera.fx=283.5 --set simulator/host=192.168.1.20), and the options below the usual ones.
The node needs a ROS master (ROS_MASTER_URI); --roscore starts a private one on a free port.

examples:
  raf bridge                                     # raf sim on this machine, default ports
  raf bridge --sim-host 192.168.1.20 --camera tcp://192.168.1.20:{CAMERA_ZMQ_PORT}   # SimTwo on another machine
  raf bridge --ns robot2 --frame-prefix robot2 {_ROBOT2}   # raf sim --robots 2's second
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..ros.cli import add_node_arguments, add_settings_arguments

    add_settings_arguments(parser, "config/bridge.yaml", "udp/port=9811")
    parser.add_argument("--sim-host", metavar="HOST", help="accept SensorFrames from this host only ('*': any)")
    parser.add_argument("--port", type=int, metavar="PORT", help=f"UDP port to listen on (default {BRIDGE_UDP_PORT})")
    cam = parser.add_mutually_exclusive_group()
    cam.add_argument("--camera", metavar="ENDPOINT", help=f"ZMQ endpoint of the camera (default tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT})")
    cam.add_argument("--no-camera", action="store_true", help="do not subscribe to the camera")
    parser.add_argument("--calibration", metavar="FILE",
                        help="camera calibration YAML from raf calibrate (the setting camera/calibration): "
                             "camera_info K and D and the camera TF")
    parser.add_argument("--defaults", action="store_true",
                        help="with --print-params: the defaults alone, as config/bridge.yaml holds them")
    add_node_arguments(parser, "raf_bridge")


def build_params(args) -> dict:
    """The override tree from --config, the global --field, the options and --set (in that order)."""
    from ..field import DEFAULT_FIELD
    from ..settings import deep_update, parse_set, read_yaml

    params: dict = read_yaml(args.config, "--config") if args.config else {}
    if getattr(args, "field", DEFAULT_FIELD) != DEFAULT_FIELD:
        params["field"] = args.field
    opts = {}
    if args.sim_host is not None:
        opts.setdefault("simulator", {})["host"] = args.sim_host
    if args.port is not None:
        opts.setdefault("udp", {})["port"] = args.port
    if args.camera:
        opts.setdefault("camera", {})["endpoint"] = args.camera
    if args.no_camera:
        opts.setdefault("camera", {})["enabled"] = False
    if getattr(args, "calibration", None):
        from pathlib import Path

        opts.setdefault("camera", {})["calibration"] = str(Path(args.calibration).resolve())
    if args.frame_prefix is not None:
        opts["frame_prefix"] = args.frame_prefix
    deep_update(params, opts)
    deep_update(params, parse_set(args.set))
    return params


def run(args) -> int:
    if args.print_params:
        from ..ros.config import HEADER, load_config
        from ..settings import to_yaml

        cfg = load_config({} if args.defaults else build_params(args))
        # --defaults: the settings as config/bridge.yaml holds them (the robot file's unset); else every value
        print(to_yaml(cfg.given, HEADER) if args.defaults else to_yaml(cfg.settings), end="")
        return 0
    return plan(args).run(args)


def plan(args):
    """The node this command line makes (:class:`~robotatfactory.ros.cli.NodePlan`), not yet started."""
    from ..ros.cli import NodePlan
    from ..ros.config import check_camera_process, load_config
    from ..ros.mw import name as middleware

    cfg = load_config(build_params(args))  # a bad name or value: a clear error before the middleware starts
    check_camera_process(cfg, middleware())

    def make_node(node):  # imported only once the middleware is up (ROS 1: --roscore sets ROS_MASTER_URI)
        from ..ros.bridge_node import Bridge
        from ..ros.config import default_params, describe_param

        node.params(default_params(), describe_param)  # ROS 2: declared (ros2 param list/describe), values = cfg's
        return Bridge(cfg, node).start()

    # the resolved settings as the node's parameters (ROS 1: rosparam shows them; ROS 2: overrides)
    return NodePlan("bridge", args.name, cfg.flat_params(), make_node,
                    lambda b: f"{args.name} listening on udp {cfg.bind_host}:{b.bound_port}")
