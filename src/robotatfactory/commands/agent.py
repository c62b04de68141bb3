"""``raf agent``: run the autonomous competition robot's node (issue 11; ROS 1 or, with ``raf --middleware ros2``, ROS 2)."""
from __future__ import annotations

import argparse

from ..simtwo.ports import SERVER_UDP_PORT

NAME = "agent"
HELP = "run the autonomous robot: factory-state server, pose from raf localize, cmd_vel and electromagnet out"
ORDER = 37
DESCRIPTION = f"""\
Run the agent node next to `raf bridge` and `raf localize`. It asks the factory-state server for the part
list and the factory's state (UDP), plans the round, and drives on the `pose` topic (never ground truth).
docs/agent.md describes what it does.

Settings: every one is in agent/settings.py (the round agent's included); `--config FILE` (the shape of
config/agent.yaml), then the options below, then `--set NAME=VALUE` (`dock.approach_speed=0.16` or
`dock/approach_speed=0.16`). `--print-params` shows the result.

examples:
  raf agent                                  # next to raf sim + raf bridge + raf localize
  raf agent --server-port {SERVER_UDP_PORT} --set max_input_age=0.3
  raf agent --config agent.yaml --set dock.approach_speed=0.16
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..agent.settings import AgentSettings, Server
    from ..ros.cli import add_node_arguments, add_settings_arguments

    add_settings_arguments(parser, "config/agent.yaml", "dock.approach_speed=0.16")
    parser.add_argument("--robot", help=f"robot file name or path (the setting robot; default {AgentSettings.robot})")
    parser.add_argument("--server-host", help=f"factory-state server host (server.host; default {Server.host})")
    parser.add_argument("--server-port", type=int,
                        help=f"factory-state server UDP port (server.port; default {Server.port})")
    parser.add_argument("--defaults", action="store_true",
                        help="with --print-params: the defaults alone, as config/agent.yaml holds them")
    add_node_arguments(parser, "raf_agent")


def settings_tree(args) -> dict:
    """The settings the command line gives, as a nested tree: ``--config``, the options, ``--set``."""
    from ..field import DEFAULT_FIELD
    from ..settings import deep_update, parse_set, read_yaml

    tree: dict = read_yaml(args.config, "--config") if args.config else {}
    if getattr(args, "field", DEFAULT_FIELD) != DEFAULT_FIELD:
        tree["field"] = args.field
    opts: dict = {}
    if args.robot is not None:
        opts["robot"] = args.robot
    if args.server_host is not None:
        opts.setdefault("server", {})["host"] = args.server_host
    if args.server_port is not None:
        opts.setdefault("server", {})["port"] = args.server_port
    deep_update(tree, opts)
    deep_update(tree, parse_set(args.set))
    return tree


def run(args) -> int:
    if getattr(args, "print_params", False):
        from ..agent.settings import HEADER, agent_settings
        from ..settings import to_yaml

        cfg = agent_settings({} if args.defaults else settings_tree(args))
        print(to_yaml(cfg, HEADER if args.defaults else ""), end="")
        return 0
    return plan(args).run(args)


def plan(args):
    """The node this command line makes (:class:`~robotatfactory.ros.cli.NodePlan`), not yet started."""
    from ..agent.settings import agent_settings
    from ..ros.cli import NodePlan

    params = settings_tree(args)
    cfg = agent_settings(params)  # a bad name or value: a clear error before the middleware starts

    def make_node(node):
        from ..ros.agent_node import AgentNode, config_from_params, node_params

        # the settings read back as the node's parameters (ROS 2 declares every one: ros2 param list)
        return AgentNode(config_from_params(node_params(node, params)), node).start()

    return NodePlan("agent", args.name, params, make_node, lambda n: f"{args.name} running (field {n.field.name}, "
                                                                f"server udp {cfg.server.host}:{cfg.server.port})")
