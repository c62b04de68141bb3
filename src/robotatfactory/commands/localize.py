"""``raf localize``: run the localization node (ArUco camera fixes + odometry + LIDAR beacons in an EKF)."""
from __future__ import annotations

import argparse

NAME = "localize"
HELP = "run the localization node: ArUco poses, EKF with odometry and LIDAR beacons, map->odom"
ORDER = 35
DESCRIPTION = """\
Run the localization node next to the bridge. Settings: every one is in the localization's settings classes
(localization/config.py and its sections; config/localization.yaml lists them with their defaults and
docs/localization.md says what each part does); `--config FILE` (the shape of config/localization.yaml), then
the options below, then `--set NAME=VALUE` (`ekf.history_s=2` or `ekf/history_s=2`; OpenCV's own detector
parameters as `detector.extra.NAME=VALUE`). `--print-params` shows the result.
ROS 1: the node needs a ROS master (ROS_MASTER_URI); --roscore starts a private one on a free port.
ROS 2 (raf --middleware ros2 localize): no master; ROS_DOMAIN_ID as for the other nodes.

examples:
  raf localize                               # next to `raf bridge`, default topics
  raf localize --set node.initial_pose=start # start from the field's start pose instead of the first fix
  raf localize --set node.filter_method=all_pnp --set pose.lone_marker_max_distance_m=0.6
  raf localize --ns robot1 --frame-prefix robot1
  raf localize --print-params
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..ros.cli import add_node_arguments, add_settings_arguments

    add_settings_arguments(parser, "config/localization.yaml", "node.use_lidar=false")
    parser.add_argument("--calibration", metavar="FILE",
                        help="camera calibration YAML from raf calibrate: intrinsics, distortion and mount (it "
                             "then takes precedence over camera_info; the setting calibration)")
    parser.add_argument("--defaults", action="store_true",
                        help="with --print-params: the defaults alone, as config/localization.yaml holds them")
    add_node_arguments(parser, "raf_localization")


def build_settings(args) -> dict:
    """The settings the command line gives, as a nested tree: ``--config``, the options, ``--set``."""
    from pathlib import Path

    from ..field import DEFAULT_FIELD
    from ..localization.config import read_yaml
    from ..settings import deep_update, parse_set

    d = read_yaml(args.config) if args.config else {}
    if getattr(args, "field", DEFAULT_FIELD) != DEFAULT_FIELD:
        d["field"] = args.field
    if args.frame_prefix is not None:
        d["frame_prefix"] = args.frame_prefix
    if getattr(args, "calibration", None):  # read with the settings' check, before the node starts
        d["calibration"] = str(Path(args.calibration).resolve())
    deep_update(d, parse_set(args.set))
    return d


def run(args) -> int:
    if args.print_params:
        from ..localization.config import HEADER, from_dict
        from ..settings import to_yaml

        cfg = from_dict({} if args.defaults else build_settings(args))
        print(to_yaml(cfg, HEADER if args.defaults else ""), end="")
        return 0
    return plan(args).run(args)


def plan(args):
    """The node this command line makes (:class:`~robotatfactory.ros.cli.NodePlan`), not yet started."""
    from ..localization.config import from_dict
    from ..ros.cli import NodePlan

    settings = build_settings(args)
    from_dict(settings)  # a bad name or value: a clear error before the middleware starts

    def make_node(node):
        from ..ros.localization_node import LocalizationNode, node_params

        # the settings read back as the node's parameters (ROS 2 declares every one: ros2 param list)
        return LocalizationNode(from_dict(node_params(node, settings)), node).start()

    return NodePlan("localize", args.name, {"": settings}, make_node,
                    lambda n: f"{args.name} running (field {n.field.name})")
