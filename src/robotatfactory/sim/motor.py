"""SimTwo's DC motor model and the low-level wheel speed controller, one wheel each, per physics step.

Plain Python floats on purpose: the simulator calls :meth:`DCMotor.step` and :meth:`SpeedPI.update` for
both wheels every 1 ms physics step, and scalar arithmetic is several times cheaper than numpy for two
values.

Motor model (SimTwo, per physics step ``dt``; SI units, w in rad/s at the wheel, gear ratio 1)::

    V  = clamp(Vref, -Vmax, Vmax)
    I' = a*I + (1 - a)*(V - Ke*w)/R,   a = exp(-dt*R/L)
    I  = clamp(I + clamp(I' - I, -slew, slew), -Imax, Imax)
    torque = Kt*I - Bv*w - Fc*sign(w)

The simulator applies ``Kt*I`` as the actuator input and lets MuJoCo add ``-Bv*w`` (joint damping,
integrated implicitly) and the Coulomb term (joint ``frictionloss``, which also holds a wheel at rest
instead of chattering around w = 0): the same law, numerically robust.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class MotorParams:
    """One DC motor. Ohm, henry, N.m/A, V.s/rad, volt, ampere, N.m.s/rad, N.m, ampere per step."""

    R: float
    L: float
    Kt: float
    Ke: float
    Vmax: float
    Imax: float
    Bv: float
    Fc: float
    slew_A_per_step: float
    gear: float = 1.0

    @classmethod
    def from_spec(cls, motor: dict) -> "MotorParams":
        return cls(**{k: float(motor[k]) for k in ("R", "L", "Kt", "Ke", "Vmax", "Imax", "Bv", "Fc",
                                                       "slew_A_per_step")}, gear=float(motor.get("gear", 1.0)))

    def no_load_speed(self, volts: float | None = None) -> float:
        """Steady wheel speed (rad/s) of a free, unloaded motor at ``volts`` (default Vmax):
        Kt*(V - Ke*w)/R = Bv*w + Fc."""
        v = self.Vmax if volts is None else min(abs(volts), self.Vmax)
        return max(0.0, (self.Kt * v / self.R - self.Fc) / (self.Kt * self.Ke / self.R + self.Bv))


class DCMotor:
    """The electrical part of SimTwo's motor model: voltage in, current and electromagnetic torque out."""

    __slots__ = ("p", "dt", "a", "b", "ke", "kt", "current", "voltage")

    def __init__(self, params: MotorParams, dt: float):
        self.p = params
        self.dt = dt
        self.a = math.exp(-dt * params.R / params.L)
        self.b = (1.0 - self.a) / params.R
        self.ke = params.Ke * params.gear  # V per rad/s of the wheel
        self.kt = params.Kt * params.gear  # N.m per A at the wheel
        self.current = 0.0  # A
        self.voltage = 0.0  # V, as applied (after the clamp)

    def reset(self) -> None:
        self.current = 0.0
        self.voltage = 0.0

    def step(self, v_ref: float, w: float) -> float:
        """Advance one physics step with voltage ``v_ref`` at wheel speed ``w``; returns Kt*I (N.m)."""
        p = self.p
        vmax = p.Vmax
        v = vmax if v_ref > vmax else (-vmax if v_ref < -vmax else v_ref)
        self.voltage = v
        i0 = self.current
        di = self.a * i0 + self.b * (v - self.ke * w) - i0
        s = p.slew_A_per_step
        if di > s:
            di = s
        elif di < -s:
            di = -s
        i = i0 + di
        imax = p.Imax
        if i > imax:
            i = imax
        elif i < -imax:
            i = -imax
        self.current = i
        return self.kt * i

    def torque(self, w: float) -> float:
        """The full SimTwo torque at wheel speed ``w`` for the present current (for analysis and tests)."""
        p = self.p
        return p.Kt * self.current * p.gear - p.Bv * w - (math.copysign(p.Fc, w) if w != 0.0 else 0.0)


@dataclass(frozen=True)
class SpeedControllerParams:
    """Wheel speed PI with feed-forward: V = kf*w_ref + kp*e + ki*integral(e), e = w_ref - w (rad/s).

    ``period`` (s) is how often the controller runs (a multiple of the physics step); ``accel_limit``
    (rad/s^2 at the wheel, 0 = none) ramps the wheel speed references so that a step in V or W does not
    exceed the tyres' grip or tip the robot onto its nose.
    """

    kp: float
    ki: float
    kf: float
    period: float
    accel_limit: float = 0.0
    kc: float = 0.0  # Coulomb feed-forward (V) added with the sign of w_ref

    @classmethod
    def from_spec(cls, sc: dict) -> "SpeedControllerParams":
        return cls(kp=float(sc["kp"]), ki=float(sc["ki"]), kf=float(sc["kf"]), period=float(sc["period"]),
                   accel_limit=float(sc.get("accel_limit", 0.0)), kc=float(sc.get("kc", 0.0)))


class SpeedPI:
    """One wheel's speed controller (anti-windup by clamping the integral so V stays within +-Vmax)."""

    __slots__ = ("p", "vmax", "dt", "integral", "ref", "target", "output", "_dv", "_kidt")

    def __init__(self, params: SpeedControllerParams, vmax: float):
        self.p = params
        self.vmax = vmax
        self.dt = params.period
        self.integral = 0.0  # V (ki * integral of the error, kept in volts)
        self.ref = 0.0  # rad/s, the ramped reference the PI tracks
        self.target = 0.0  # rad/s, the reference asked for
        self.output = 0.0  # V
        self._dv = params.accel_limit * params.period if params.accel_limit > 0 else math.inf
        self._kidt = params.ki * params.period

    def reset(self) -> None:
        self.integral = self.ref = self.target = self.output = 0.0

    def update(self, w: float) -> float:
        """Run one controller period at measured wheel speed ``w``; returns the voltage reference."""
        p = self.p
        t, r, dv = self.target, self.ref, self._dv
        if t - r > dv:
            r += dv
        elif r - t > dv:
            r -= dv
        else:
            r = t
        self.ref = r
        e = r - w
        integral = self.integral + self._kidt * e
        u = p.kf * r + (p.kc if r > 0.0 else (-p.kc if r < 0.0 else 0.0)) + p.kp * e + integral
        vmax = self.vmax
        if u > vmax:  # conditional integration: do not wind up beyond saturation
            if self._kidt * e > 0:
                integral = self.integral
            u = vmax
        elif u < -vmax:
            if self._kidt * e < 0:
                integral = self.integral
            u = -vmax
        self.integral = integral
        self.output = u
        return u
