"""``raf simctl``: one request to a running ``raf sim``'s control channel (no ROS needed), its reply printed.

The same requests as the bridge's ``sim/*`` services (docs/protocol.md, "Control channel"); exit code 0 when
the simulator answered ``ok``, 1 when it refused (the error is printed), 2 on a usage error or no answer.
"""
from __future__ import annotations

import argparse

from ..sim.control import CONTROL_PORT_OFFSET
from ..simtwo.ports import LOCALHOST, SIMTWO_UDP_PORT

CONTROL = f"{LOCALHOST}:{SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}"  # raf sim's control channel by default
NAME = "simctl"
HELP = "control a running raf sim: reset, pause, resume, step, set_robot_pose, place_part, remove_part, get_state"
ORDER = 25
DESCRIPTION = f"""\
Send one request to raf sim's control channel (UDP, JSON; default {CONTROL}, the command port + {CONTROL_PORT_OFFSET}) and
print the reply.

  raf simctl get_state
  raf simctl pause
  raf simctl step 25                            25 control cycles (1 s) of a paused simulation
  raf simctl resume
  raf simctl set_robot_pose -0.4 -0.35 0.5      x, y (m), theta (rad), field frame
  raf simctl place_part 1 --slot outgoing_2     or: raf simctl place_part 1 --at 0.1 0.2 1.57
  raf simctl remove_part 1
  raf simctl reset --round 2 --seed 3 --parts RGBX

docs/protocol.md describes the requests and their replies."""

OPS = ("get_state", "pause", "resume", "step", "set_robot_pose", "place_part", "remove_part", "reset")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("op", choices=OPS, help="the request")
    parser.add_argument("values", nargs="*", type=float, metavar="N",
                        help="step: cycles; set_robot_pose: x y theta; place_part, remove_part: the part id")
    parser.add_argument("--control", default=CONTROL, metavar="HOST:PORT",
                        help=f"raf sim's control channel (default {CONTROL})")
    parser.add_argument("--slot", help="place_part: a slot of the field, e.g. outgoing_2")
    parser.add_argument("--at", nargs=3, type=float, metavar=("X", "Y", "FACING"),
                        help="place_part: a pose (m, m, rad: the plate's heading)")
    parser.add_argument("--type", choices=("R", "G", "B"), help="place_part: recolour the part")
    parser.add_argument("--round", type=int, choices=(1, 2, 3), help="reset: the round")
    parser.add_argument("--seed", type=int, help="reset: the seed")
    parser.add_argument("--parts", metavar="RGBX", help="reset: the incoming layout")
    parser.add_argument("--start-pose", nargs=3, type=float, metavar=("X", "Y", "THETA"), help="reset: the start pose")
    parser.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for the reply (default 2; "
                                                                   "step and reset wait longer)")


def _request(args) -> dict:
    from ..errors import ConfigError

    op, v = args.op, args.values
    want = {"step": (1,), "set_robot_pose": (2, 3), "place_part": (1,), "remove_part": (1,)}.get(op, (0,))
    if len(v) not in want:
        raise ConfigError(f"raf simctl {op}: expected {' or '.join(map(str, want))} number(s), got {len(v)}")
    req: dict = {}
    if op == "step":
        req["cycles"] = int(v[0])
    elif op == "set_robot_pose":
        req.update(x=v[0], y=v[1], theta=v[2] if len(v) > 2 else 0.0)
    elif op in ("place_part", "remove_part"):
        req["part"] = int(v[0])
    if op == "place_part":
        if (args.slot is None) == (args.at is None):
            raise ConfigError("raf simctl place_part: give --slot NAME or --at X Y FACING")
        if args.slot is not None:
            req["slot"] = args.slot
        else:
            req.update(x=args.at[0], y=args.at[1], facing=args.at[2])
        if args.type:
            req["type"] = args.type
    if op == "reset":
        for key, val in (("round", args.round), ("seed", args.seed), ("parts", args.parts),
                         ("start_pose", list(args.start_pose) if args.start_pose else None)):
            if val is not None:
                req[key] = val
    return req


def run(args) -> int:
    import json

    from ..sim.control import ControlClient
    from ..sim.runner import parse_address

    req = _request(args)
    client = ControlClient(parse_address(args.control), timeout=args.timeout)
    try:
        reply = client.request(args.op, **req)
    except ConnectionError as e:
        print(f"raf simctl: {e} (is raf sim running, with its control channel there?)")
        return 2
    print(json.dumps(reply, indent=1))
    return 0 if reply.get("ok") else 1
