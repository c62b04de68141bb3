"""Bring a pose estimate forward to now: the estimate is ``age`` seconds old when the controller uses it
(the EKF's stamp, the transport, the control timer), and a turning robot moves a lot in that time
(3 rad/s x 80 ms = 0.24 rad). Unicycle motion at constant body speeds (v m/s, w rad/s) in the field frame.
"""
from __future__ import annotations

from ..localization.geometry import compose2, se2_exp


def extrapolate(pose: tuple[float, float, float], v: float, w: float, age: float) -> tuple[float, float, float]:
    """The pose (x, y, theta; m, rad) after ``age`` s at speeds (v, w); exact on the arc."""
    if age <= 0.0:
        return tuple(pose)
    return compose2(pose, se2_exp((v * age, 0.0, w * age)))
