"""What the nodes and their commands share: the common options, running a node (on either middleware: see
:mod:`.mw`), and the periodic diagnostics publisher."""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
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


def run_node(args, who: str, params: dict, make_node: Callable, started: Callable[[object], str]) -> int:
    """Run one node from the command line until Ctrl-C, on this process's middleware (:mod:`.mw`).

    ``args`` carries ``roscore``, ``ns``, ``name`` and ``no_sim_time``; ``params`` maps parameter paths
    relative to the node (``""`` for the node's whole namespace) to values, given to the node as if a launch
    file had loaded them (ROS 1: set on the master, so ``rosparam`` shows them; ROS 2: parameter overrides);
    ``make_node(node)`` builds and starts the node object on the middleware's :class:`~.mw.base.Node`;
    ``started(obj)`` is the line printed once it runs.
    """
    from .mw import api

    return api().run_node(args, who, params, make_node, started)


@dataclass
class NodePlan:
    """A node as a command line makes it, not yet started: what :func:`run_node` runs alone and
    :func:`run_nodes` runs with others in one process (``raf compose``)."""

    who: str  #: the command (``bridge``): names the node in messages
    name: str  #: the node's name (``raf_bridge``)
    params: dict  #: as :func:`run_node`'s ``params`` (``{}``: none)
    make_node: Callable[[object], object]  #: ``make_node(node) -> obj`` (obj has ``stop()``)
    started: Callable[[object], str]  #: ``started(obj) -> str``, the line printed once it runs
    #: releases what the plan holds outside its node (record's bag, opened by ``make_node``), whether or not the
    #: node started or stopped: called once the node is done, by :meth:`run` and by :func:`run_nodes`
    close: Callable[[], None] | None = None

    def run(self, args) -> int:
        try:
            return run_node(args, self.who, self.params, self.make_node, self.started)
        finally:
            if self.close is not None:
                self.close()


def run_nodes(args, plans: list[NodePlan]) -> int:
    """Run ``plans`` as components of one process until Ctrl-C (``raf compose``): ``args`` as for
    :func:`run_node`, its ``name`` the process's node. Messages between the components go in-process
    (:mod:`.mw.local`). ROS 1 only: rospy has one node per process (ConfigError on ROS 2)."""
    from .mw import api

    impl = api()
    if not hasattr(impl, "run_nodes"):
        from ..errors import ConfigError

        raise ConfigError(f"raf compose: not on {impl.NAME} (ROS 1 only); run the nodes one by one")
    return impl.run_nodes(args, plans)


def spin_node(name: str, make_node: Callable, argv: list[str] | None = None) -> int:
    """A node's ``main`` under a launch file: init, ``make_node(node)`` (which reads the node's parameters),
    spin, stop. A bad parameter (ConfigError) is logged as fatal and ends the node with exit code 2."""
    from .mw import api

    return api().spin_node(name, make_node, argv)


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
