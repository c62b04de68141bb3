"""``raf referee``: the competition's factory and referee for the real SimTwo (ROS 1, or ROS 2 with
``raf --middleware ros2``)."""
from __future__ import annotations

import argparse

from ..simtwo.ports import SERVER_UDP_PORT

NAME = "referee"
HELP = "the factory and referee for a simulator that reports its parts (the real SimTwo): server, machines, score"
ORDER = 41
DESCRIPTION = """\
Run next to `raf bridge` when the simulator is the real SimTwo (raf sim runs its own factory and referee),
with the field of SimTwo's scene (raf --field simtwo2022 referee).
From what the bridge publishes of each SensorFrame (ground_truth, ground_truth/parts from control.pas,
electromagnet/state) it keeps the factory's state, serves the factory-state protocol over UDP on the
simulation clock (the agent's IWP OWP MAP MBP CTL), runs the machines (moving processed parts through the
bridge's sim/place_part; SimTwo cannot recolour a part, the server reports its new type), scores the run by
the rules and prints the final report when stopped (Ctrl-C). docs/competition.md, "The referee on SimTwo".

examples:
  raf --field simtwo2022 referee --round 2 --seed 3 --start-after 3
  raf --field simtwo2022 referee --round 1 --trace run.jsonl --end-after-max 1
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..competition.live import READY_TIMEOUT
    from ..ros.cli import add_node_arguments

    parser.add_argument("--round", type=int, default=1, choices=(1, 2, 3), help="round 1, 2 or 3 (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the organiser's part draw (default 0)")
    parser.add_argument("--parts", metavar="RGBX", default="",
                        help="incoming parts, slot 1 first (R, G, B, X = empty); overrides the seeded draw. They "
                             "must be where SimTwo's scene put them: raf simtwo run --round/--seed/--parts")
    parser.add_argument("--duration", type=float, default=600.0, help="round length, s (default 600)")
    parser.add_argument("--start-after", type=float, default=3.0, metavar="S",
                        help="simulation seconds after the first frame before the run starts (default 3)")
    parser.add_argument("--ready-topic", metavar="TOPIC", default="",
                        help="wait for the robot: the run starts no earlier than the first message on TOPIC "
                             "(geometry_msgs/PoseWithCovarianceStamped, e.g. pose: its localization has a pose), "
                             "as a referee waits for a team's ready sign; at most " + f"{READY_TIMEOUT:g} s after the first "
                             "frame (default: no wait)")
    parser.add_argument("--server-host", default="127.0.0.1", help="address the factory-state server binds")
    parser.add_argument("--server-port", type=int, default=SERVER_UDP_PORT,
                        help=f"factory-state server UDP port (default {SERVER_UDP_PORT})")
    parser.add_argument("--trace", metavar="FILE", default="",
                        help="write the ground truth cycle by cycle (raf sim --trace's format)")
    parser.add_argument("--end-after-max", type=float, default=-1.0, metavar="S",
                        help="stop once the maximum score has stood S simulation seconds (default: never)")
    parser.add_argument("--status-every", type=float, default=5.0, metavar="S",
                        help="simulation seconds between score lines (default 5; 0: none)")
    add_node_arguments(parser, "raf_referee")


def run(args) -> int:
    from dataclasses import asdict

    from ..field import DEFAULT_FIELD
    from ..ros.referee_node import RefereeConfig, config_from_params

    cfg = config_from_params(asdict(RefereeConfig(
        field=getattr(args, "field", DEFAULT_FIELD), round=args.round, seed=args.seed, parts=args.parts,
        duration=args.duration, start_after=args.start_after, server_host=args.server_host,
        server_port=args.server_port, trace=args.trace, end_after_max=args.end_after_max,
        status_every=args.status_every, ready_topic=args.ready_topic)))
    # the round's layout is checked now (a bad --parts is an error here, not in the node)
    from ..competition import RoundSetup

    setup = RoundSetup.make(cfg.round, cfg.seed, cfg.parts or None, duration=cfg.duration)
    if args.print_params:
        print(cfg)
        return 0
    from ..ros.cli import run_node

    params = asdict(cfg)

    def make_node(node):
        from ..ros.referee_node import RefereeNode, node_params

        return RefereeNode(config_from_params(node_params(node, params)), node).start()

    return run_node(args, "referee", params, make_node,
                    lambda n: f"{args.name} running (field {n.field.name}, {setup.describe()}, factory-state server "
                              f"udp {n.server.address[0]}:{n.server.address[1]})")
