"""``raf localize``: run the localization node (ArUco camera fixes + odometry + LIDAR beacons in an EKF)."""
from __future__ import annotations

import argparse

NAME = "localize"
HELP = "run the localization node: ArUco poses, EKF with odometry and LIDAR beacons, map->odom"
ORDER = 35
DESCRIPTION = """\
Run the localization node next to the bridge. Settings: config/localization.yaml (every key in
docs/localization.md); --config FILE overrides them from a YAML file of the same shape, --set NAME=VALUE one
by one (e.g. --set node/filter_method=all_pnp --set pose/lone_marker_max_distance_m=0.6).
ROS 1: the node needs a ROS master (ROS_MASTER_URI); --roscore starts a private one on a free port.
ROS 2 (raf --middleware ros2 localize): no master; ROS_DOMAIN_ID as for the other nodes.

examples:
  raf localize                               # next to `raf bridge`, default topics
  raf localize --set node/initial_pose=start # start from the field's start pose instead of the first fix
  raf localize --ns robot1 --frame-prefix robot1
  raf localize --print-params
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..ros.cli import add_node_arguments, add_settings_arguments

    add_settings_arguments(parser, "config/localization.yaml", "node/use_lidar=false")
    parser.add_argument("--calibration", metavar="FILE",
                        help="camera calibration YAML from raf calibrate: intrinsics, distortion and mount (it "
                             "then takes precedence over camera_info)")
    add_node_arguments(parser, "raf_localization")


def build_settings(args) -> dict:
    from pathlib import Path

    from ..field import DEFAULT_FIELD
    from ..localization.config import DEFAULT_FILE, read_yaml
    from ..settings import deep_update, parse_set

    d = read_yaml(args.config) if args.config else (read_yaml(DEFAULT_FILE) if DEFAULT_FILE.is_file() else {})
    if getattr(args, "field", DEFAULT_FIELD) != DEFAULT_FIELD:
        d["field"] = args.field
    if args.frame_prefix is not None:
        d["frame_prefix"] = args.frame_prefix
    if getattr(args, "calibration", None):  # checked with the settings (from_dict), before the node starts
        d["calibration"] = str(Path(args.calibration).resolve())
    deep_update(d, parse_set(args.set))
    return d


def _plain(obj):
    from dataclasses import asdict, is_dataclass

    return asdict(obj) if is_dataclass(obj) else obj


def run(args) -> int:
    import yaml

    from ..localization.config import from_dict

    settings = build_settings(args)
    cfg = from_dict(settings)
    if args.print_params:
        print(yaml.safe_dump({k: _plain(getattr(cfg, k)) for k in cfg.__dataclass_fields__}, sort_keys=False), end="")
        return 0
    from ..ros.cli import run_node

    def make_node(node):
        from ..ros.localization_node import LocalizationNode, node_params

        # the settings read back as the node's parameters (ROS 2 declares every one: ros2 param list)
        return LocalizationNode(from_dict(node_params(node, settings)), node).start()

    return run_node(args, "localize", {"": settings}, make_node,
                    lambda n: f"{args.name} running (field {n.field.name})")
