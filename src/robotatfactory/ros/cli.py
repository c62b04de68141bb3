"""What ``raf bridge`` and ``raf localize`` share: a master, the node's parameters, init, spin, clean-up."""
from __future__ import annotations

import sys
from typing import Callable


def read_private_params() -> dict:
    """The node's private parameters as a nested dict (``~udp/port`` -> ``{"udp": {"port": ...}}``)."""
    import rospy

    p = rospy.get_param("~", {})
    return p if isinstance(p, dict) else {}


def run_node(args, who: str, params: dict, make_node: Callable[[], object], started: Callable[[object], str]) -> int:
    """Run one node from the command line until Ctrl-C.

    ``args`` carries ``roscore``, ``ns``, ``name`` and ``no_sim_time``; ``params`` maps parameter paths
    relative to the node (``""`` for the node's whole namespace) to values, set on the master so that
    ``rosparam`` shows them as if a launch file had loaded them; ``make_node()`` builds and starts the node
    after ``rospy.init_node``; ``started(node)`` is the line printed once it runs.
    """
    from .master import ensure_master

    master = ensure_master(args.roscore, who)
    import rosgraph
    import rospy

    ns = args.ns.strip("/")
    path = f"/{ns}/{args.name}" if ns else f"/{args.name}"
    m = rosgraph.Master(f"/raf_{who}_cli")
    if not args.no_sim_time:
        m.setParam("/use_sim_time", True)
    for key, value in params.items():
        m.setParam(f"{path}/{key}" if key else path, list(value) if isinstance(value, tuple) else value)
    rospy.init_node(args.name, argv=[sys.argv[0]] + ([f"__ns:=/{ns}"] if ns else []))
    node = make_node()
    print(f"raf {who}: {started(node)}", flush=True)
    try:
        rospy.spin()
    finally:
        node.stop()
        if master is not None:
            master.stop()
    return 0
