"""Bring a pose estimate forward to now: the estimate is ``age`` seconds old when the controller uses it
(the EKF's stamp, the transport, the control timer), and a turning robot moves a lot in that time
(3 rad/s x 80 ms = 0.24 rad). Unicycle motion at constant body speeds (v m/s, w rad/s) in the field frame.
"""
from __future__ import annotations

import math


def extrapolate(pose: tuple[float, float, float], v: float, w: float, age: float) -> tuple[float, float, float]:
    """The pose (x, y, theta; m, rad) after ``age`` s at speeds (v, w); exact on the arc."""
    x, y, th = pose
    if age <= 0.0:
        return (x, y, th)
    dth = w * age
    if abs(dth) < 1e-9:
        return (x + v * age * math.cos(th), y + v * age * math.sin(th), th)
    r = v / w
    th2 = th + dth
    return (x + r * (math.sin(th2) - math.sin(th)), y - r * (math.cos(th2) - math.cos(th)),
            math.atan2(math.sin(th2), math.cos(th2)))
