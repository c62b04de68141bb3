"""One node layer, two middlewares: the small interface every robotatfactory node is written against.

A node (bridge, camera, localization, agent, simulation services) is written once against :class:`Node`
(:mod:`.base`): publishers and subscribers with a QoS *intent*, services, timers on the node's clock
(simulation time under ``use_sim_time``), parameters, TF, logging. :mod:`.ros1` implements it on rospy
(Debian's ROS 1), :mod:`.ros2` on rclpy (ROS 2 Jazzy wheels from PyPI). Message classes are imported by
the node files as usual (``from nav_msgs.msg import Odometry``): both middlewares ship Python packages of
the same names, which is also why one interpreter holds only one of them (``.venv`` sees Debian's ROS 1,
``.venv-ros2`` holds the Jazzy wheels; ``raf --middleware ros2 ...`` runs the second).

Which middleware a process uses: ``RAF_MIDDLEWARE`` (``ros1`` / ``ros2``) when set, else the one this
interpreter can import (rclpy -> ros2, rospy -> ros1).
"""
from __future__ import annotations

import importlib
import os
from types import ModuleType

from .base import QoS  # noqa: F401  (re-exported: node files use mw.QoS.SENSOR etc.)

MIDDLEWARES = ("ros1", "ros2")
#: the Python package each middleware's interpreter must be able to import
PACKAGES = {"ros1": "rospy", "ros2": "rclpy"}
_API: ModuleType | None = None


def importable(middleware: str) -> bool:
    """Whether this interpreter can import ``middleware`` (without importing it)."""
    import importlib.util

    return importlib.util.find_spec(PACKAGES[middleware]) is not None


def available() -> list[str]:
    """The middlewares this interpreter can import (usually exactly one)."""
    return [m for m in MIDDLEWARES if importable(m)]


# ---- what a middleware can do, asked by name (also for another interpreter's: nothing is imported) --------

def has_master(middleware: str | None = None) -> bool:
    """Whether ``middleware`` (default: this process's) has a master every node registers with (ROS 1's
    roscore, which must be running first); ROS 2's nodes find each other by discovery (a domain id)."""
    return (middleware or name()) == "ros1"


def bag_format(middleware: str | None = None) -> str:
    """The bag ``middleware`` (default: this process's) records: ``bag`` (a ROS 1 bag, a file) or ``mcap``
    (a rosbag2, a directory, with MCAP storage). A middleware records only its own generation's bags."""
    return "mcap" if (middleware or name()) == "ros2" else "bag"


def name() -> str:
    """The middleware of this process: ``RAF_MIDDLEWARE`` if set, else the importable one (ros1 first)."""
    want = os.environ.get("RAF_MIDDLEWARE", "").strip().lower()
    if want:
        if want not in MIDDLEWARES:
            from ...errors import ConfigError

            raise ConfigError(f"RAF_MIDDLEWARE={want!r}: use one of {', '.join(MIDDLEWARES)}")
        return want
    have = available()
    if not have:
        from ...errors import ConfigError

        raise ConfigError("neither rospy (ROS 1) nor rclpy (ROS 2) can be imported by this Python: run "
                          "scripts/bootstrap.sh, then .venv/bin/raf (ROS 1) or raf --middleware ros2 ...")
    return have[0]


def api() -> ModuleType:
    """The implementation module (:mod:`.ros1` or :mod:`.ros2`) of this process's middleware."""
    global _API
    if _API is None:
        _API = module(name())
    return _API


def module(middleware: str) -> ModuleType:
    """The implementation module of ``middleware`` (importing it imports the middleware: only an interpreter
    that has it can)."""
    if middleware not in MIDDLEWARES:
        raise ValueError(f"unknown middleware {middleware!r}: one of {', '.join(MIDDLEWARES)}")
    return importlib.import_module(f"{__name__}.{middleware}")
