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
_API: ModuleType | None = None


def available() -> list[str]:
    """The middlewares this interpreter can import (usually exactly one)."""
    import importlib.util

    return [m for m, mod in (("ros1", "rospy"), ("ros2", "rclpy")) if importlib.util.find_spec(mod) is not None]


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
        _API = importlib.import_module(f"{__name__}.{name()}")
    return _API
