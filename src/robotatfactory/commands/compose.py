"""``raf compose``: several nodes (bridge, localize, agent, record) as components of one process (ROS 1)."""
from __future__ import annotations

import argparse

NAME = "compose"
HELP = "run several nodes (bridge, localize, agent, record) in one process, their messages in-process (ROS 1)"
ORDER = 39
COMPOSABLE = ("bridge", "localize", "agent", "record")
DESCRIPTION = f"""\
Run several nodes as components of one process, as nodelets do in ROS 1: each keeps its name, its parameters
and its topics, and the messages between them are handed over in-process (no serialization, no socket);
other processes see the same topics as from separate nodes (rosnode shows the process's node, --name). Each
node is given as its own command line after `--`, with every option of that command (`raf bridge --help`);
they share the process's namespace (--ns) and clock. Composable: {', '.join(COMPOSABLE)}. ROS 1 only (rospy
has one node per process; on ROS 2 run the nodes one by one). One process: a node that ends (record
--duration, a fatal error) ends them all. docs/pacing.md says what it saves.

examples:
  raf compose -- bridge -- localize -- agent
  raf --field simtwo2022 compose --roscore -- bridge --port 9811 -- localize -- agent -- record -o run.bag
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ns", metavar="NS", default="", help="ROS namespace of the process and its nodes")
    parser.add_argument("--name", default="raf_compose", help="the process's node name (default raf_compose)")
    parser.add_argument("--no-sim-time", action="store_true", help="do not set /use_sim_time")
    parser.add_argument("--roscore", action="store_true", help="start a private roscore on a free port")
    parser.add_argument("nodes", nargs=argparse.REMAINDER, metavar="-- COMMAND [ARGS] ...",
                        help=f"each node's command line ({', '.join(COMPOSABLE)}), each after `--`")


def split(tokens: list[str]) -> list[list[str]]:
    """``["--", "bridge", "--port", "1", "--", "agent"]`` -> ``[["bridge", "--port", "1"], ["agent"]]``."""
    parts: list[list[str]] = [[]]
    for tok in tokens:
        if tok == "--":
            parts.append([])
        else:
            parts[-1].append(tok)
    return [p for p in parts if p]


def plans(args) -> list:
    """Each node's plan (:class:`~robotatfactory.ros.cli.NodePlan`) from its command line; ConfigError for a
    command that cannot be composed, two nodes of one name, or a node in another namespace."""
    from ..cli import build_parser
    from ..errors import ConfigError
    from ..registry import discover
    from .. import commands

    modules = discover(commands)
    parts = split(args.nodes)
    if not parts:
        raise ConfigError(f"no node given: raf compose -- COMMAND [ARGS] -- ... ({', '.join(COMPOSABLE)})")
    out, names = [], set()
    for part in parts:
        if part[0] not in COMPOSABLE:
            raise ConfigError(f"{part[0]!r} cannot be composed: one of {', '.join(COMPOSABLE)}, each after `--`")
        try:
            sub = build_parser().parse_args(["--field", args.field, *part])
        except SystemExit as e:  # argparse printed what is wrong with that node's command line
            raise ConfigError(f"bad command line for {part[0]}: {' '.join(part)}") from e
        if sub.ns.strip("/") != args.ns.strip("/"):
            raise ConfigError(f"{part[0]}: --ns {sub.ns!r}: the components share the process's namespace "
                              f"(raf compose --ns {args.ns or '/'})")
        if sub.name in names:
            raise ConfigError(f"two nodes named {sub.name!r}: give one --name")
        names.add(sub.name)
        out.append(modules[part[0]].plan(sub))
    return out


def run(args) -> int:
    from ..ros.cli import run_nodes

    return run_nodes(args, plans(args))
