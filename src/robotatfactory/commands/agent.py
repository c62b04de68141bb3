"""``raf agent``: run the autonomous competition robot's node (issue 11; ROS 1 or, with ``raf --middleware ros2``, ROS 2)."""
from __future__ import annotations

import argparse

from ..simtwo.ports import SERVER_UDP_PORT

NAME = "agent"
HELP = "run the autonomous robot: factory-state server, pose from raf localize, cmd_vel and electromagnet out"
ORDER = 37
DESCRIPTION = """\
Run the agent node next to `raf bridge` and `raf localize`. It asks the factory-state server for the part
list and the factory's state (UDP), plans the round, and drives on the `pose` topic (never ground truth).
docs/agent.md describes what it does.

examples:
  raf agent                                  # next to raf sim + raf bridge + raf localize
  raf agent --server-port 44832 --max-input-age 0.3
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..ros.cli import add_node_arguments

    parser.add_argument("--robot", default="simtwo", help="robot file name or path (default simtwo)")
    parser.add_argument("--server-host", default="127.0.0.1", help="factory-state server host")
    parser.add_argument("--server-port", type=int, default=SERVER_UDP_PORT,
                        help=f"factory-state server UDP port (default {SERVER_UDP_PORT})")
    parser.add_argument("--max-input-age", type=float, default=0.5,
                        help="seconds after which pose/odom count as stale (the robot stops)")
    parser.add_argument("--command-latency", type=float, default=0.08, metavar="S",
                        help="seconds from publishing cmd_vel to the simulator's cycle that runs it: the pose is "
                             "predicted that far ahead through the commands in flight (default 0.08: SimTwo's and "
                             "raf sim's two cycles; 0: no prediction beyond now)")
    add_node_arguments(parser, "raf_agent")


def run(args) -> int:
    from ..errors import ConfigError
    from ..field import DEFAULT_FIELD

    if not args.max_input_age > 0:
        raise ConfigError(f"--max-input-age must be > 0 s, got {args.max_input_age}")
    if not 0 <= args.command_latency <= 1:
        raise ConfigError(f"--command-latency must be 0..1 s, got {args.command_latency}")
    from ..ros.agent_node import AgentNodeConfig

    cfg = AgentNodeConfig(field=getattr(args, "field", DEFAULT_FIELD), robot=args.robot,
                          server_host=args.server_host, server_port=args.server_port,
                          max_input_age=args.max_input_age, command_latency=args.command_latency)
    if getattr(args, "print_params", False):
        print(cfg)
        return 0
    from dataclasses import asdict

    from ..ros.cli import run_node

    params = asdict(cfg)

    def make_node(node):
        from ..ros.agent_node import AgentNode, config_from_params, node_params

        # the settings read back as the node's parameters (ROS 2 declares every one: ros2 param list)
        return AgentNode(config_from_params(node_params(node, params)), node).start()

    return run_node(args, "agent", params, make_node, lambda n: f"{args.name} running (field {n.field.name}, "
                                                           f"server udp {cfg.server_host}:{cfg.server_port})")
