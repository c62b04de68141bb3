"""What the nodes and their commands share: a master, the node's parameters, init, spin, clean-up, and the
periodic diagnostics publisher."""
from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import Callable


def add_node_arguments(parser: argparse.ArgumentParser, default_name: str) -> None:
    """The options every node command takes, added after the command's own."""
    parser.add_argument("--ns", metavar="NS", default="", help="ROS namespace of the node and its topics")
    parser.add_argument("--frame-prefix", metavar="PREFIX", help="prefix of the robot's TF frames (robot1/base_link)")
    parser.add_argument("--name", default=default_name, help=f"node name (default {default_name})")
    parser.add_argument("--no-sim-time", action="store_true",
                        help="do not set /use_sim_time (the bridge publishes /clock in any case)")
    parser.add_argument("--roscore", action="store_true", help="start a private roscore on a free port")
    parser.add_argument("--print-params", action="store_true", help="print the resolved settings as YAML and exit")


def add_settings_arguments(parser: argparse.ArgumentParser, config_file: str, example: str) -> None:
    parser.add_argument("--config", metavar="FILE", help=f"YAML settings (same shape as {config_file})")
    parser.add_argument("--set", metavar="NAME=VALUE", action="append", default=[],
                        help=f"set one setting, e.g. {example} (repeatable)")


def read_private_params() -> dict:
    """The node's private parameters as a nested dict (``~udp/port`` -> ``{"udp": {"port": ...}}``)."""
    import rospy

    p = rospy.get_param("~", {})
    return p if isinstance(p, dict) else {}


def loopback_ros_default() -> None:
    """With the master on this machine and neither ROS_IP nor ROS_HOSTNAME set, let this node's XML-RPC and
    TCPROS servers listen on 127.0.0.1 (rospy binds every interface otherwise). Before ``init_node``."""
    import os
    from urllib.parse import urlparse

    if os.environ.get("ROS_IP") or os.environ.get("ROS_HOSTNAME"):
        return
    host = urlparse(os.environ.get("ROS_MASTER_URI", "http://localhost:11311/")).hostname or ""
    if host == "localhost" or host.startswith("127."):
        os.environ["ROS_IP"] = "127.0.0.1"


MASTER_RESTARTED = 4  # exit code of a node whose ROS master restarted under it


def master_pid() -> int | None:
    """The ROS master's process id, or None when no master answers (read before ``init_node``, so that a
    master restarted while the node starts up is noticed by :func:`watch_master`)."""
    import rosgraph

    try:
        return int(rosgraph.Master("/raf_master_pid").getPid())
    except Exception:  # noqa: BLE001 - no master (reported elsewhere)
        return None


def watch_master(who: str, period: float = 1.0, pid0: int | None = None) -> dict:
    """Watch the ROS master from a daemon thread: when it restarts (a new process answers at the same URI),
    rospy cannot re-register this node's publishers and subscribers with it, so the node would go on deaf
    and mute. Log a clear message and shut the node down instead (roslaunch ``respawn="true"`` or the user
    starts it again). ``pid0``: the master's pid read before the node registered (default: read now).
    Returns a dict whose ``"restarted"`` is set True when that happened."""
    import rosgraph
    import rospy

    state = {"restarted": False}
    m = rosgraph.Master(rospy.get_name() or f"/raf_{who}")
    if pid0 is None:
        try:
            pid0 = m.getPid()
        except Exception:  # noqa: BLE001 - no master to watch (it will be reported elsewhere)
            return state

    def loop():
        lost = False
        while not rospy.is_shutdown():
            time.sleep(period)
            try:
                pid = m.getPid()
            except Exception:  # noqa: BLE001 - master down: wait for it to come back
                if not lost:
                    rospy.logwarn(f"{who}: the ROS master at {rosgraph.get_master_uri()} does not answer; "
                                  "waiting for it (topics already connected keep flowing)")
                lost = True
                continue
            if pid != pid0:
                state["restarted"] = True
                rospy.logfatal(f"{who}: the ROS master restarted (pid {pid0} -> {pid}); rospy cannot register this "
                               "node's topics with the new master, so the node exits (exit code "
                               f"{MASTER_RESTARTED}): start it again, or use respawn=\"true\" under roslaunch")
                rospy.signal_shutdown("the ROS master restarted")
                return
            if lost:
                rospy.loginfo(f"{who}: the ROS master answers again (same process)")
                lost = False

    threading.Thread(target=loop, name=f"raf-{who}-master-watch", daemon=True).start()
    return state


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
    loopback_ros_default()
    pid0 = master_pid()
    if ns:
        # rospy takes its namespace from ROS_NAMESPACE / __ns when it is imported; an __ns given to init_node
        # later is not read (rospy/names.py sets _caller_id at import, init_node resolves the node name
        # against it): set it here
        import os

        os.environ["ROS_NAMESPACE"] = f"/{ns}"
        rospy.names._set_caller_id(f"/{ns}/unnamed")
    rospy.init_node(args.name, argv=[sys.argv[0]] + ([f"__ns:=/{ns}"] if ns else []))
    node = make_node()
    print(f"raf {who}: {started(node)}", flush=True)
    watch = watch_master(f"raf {who}", pid0=pid0)
    try:
        rospy.spin()
    finally:
        node.stop()
        if master is not None:
            master.stop()
    return MASTER_RESTARTED if watch["restarted"] else 0


def spin_node(name: str, make_node: Callable[[], object], argv: list[str] | None = None) -> int:
    """A node's ``main`` under roslaunch: init, build from the private parameters, spin, stop.

    A bad parameter (ConfigError from ``make_node``) is logged as fatal and ends the node with exit code 2.
    """
    import rospy

    from ..errors import ConfigError

    loopback_ros_default()
    pid0 = master_pid()
    rospy.init_node(name, argv=argv if argv is not None else sys.argv)
    try:
        node = make_node()
    except ConfigError as e:
        rospy.logfatal(f"{name}: {e}")
        return 2
    watch = watch_master(name, pid0=pid0)
    rospy.spin()
    node.stop()
    return MASTER_RESTARTED if watch["restarted"] else 0


def publish_every(period: float, running: Callable[[], bool], pub, make: Callable[[], object],
                  errors: tuple = (), on_error: Callable[[Exception], None] | None = None) -> None:
    """Publish ``make()`` on ``pub`` every ``period`` seconds of wall time while ``running()`` (a thread's body).

    Wall time, not simulation time, so that diagnostics keep coming when the simulation stops. An exception
    of a type in ``errors`` is passed to ``on_error`` (if given) and the loop goes on; others propagate.
    """
    nxt = time.monotonic()
    while running():
        nxt += period
        try:
            pub.publish(make())
        except errors as e:
            if on_error is not None:
                on_error(e)
        time.sleep(max(0.0, nxt - time.monotonic()))
