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


# ------------------------------------------------------------------------------------------------------------
# SimTwo's own wheel speed controller
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SimTwoPIDParams:
    """The gains and timing of SimTwo's motor controller (``TMotController``, ODERobots.pas 47-54).

    ``kp``, ``ki``, ``kd``, ``kf`` as ``SetMotorControllerPars(R, i, Ki, Kd, Kp, Kf)`` sets them
    (ODERobotsPublished.pas 1785-1794); ``period`` (s) is the scene XML's ``<controller period='10'/>``
    (in ms there, Viewer.pas 3095; no script call changes it); ``y_sat`` (V) is the motor's ``vmax``
    (Viewer.pas 3065); ``ode_dt`` (s) is SimTwo's physics step ``Ode_dt := 1/1000`` (Viewer.pas 4240), which
    CalcPID uses for its integral and derivative whatever ``period`` is.
    """

    kp: float
    ki: float
    kd: float
    kf: float
    period: float = 0.01
    y_sat: float = 8.2
    ode_dt: float = 0.001

    @classmethod
    def from_spec(cls, pid: dict, ode_dt: float = 0.001) -> "SimTwoPIDParams":
        return cls(kp=float(pid["kp"]), ki=float(pid["ki"]), kd=float(pid["kd"]), kf=float(pid["kf"]),
                   period=float(pid.get("period", 0.01)), y_sat=float(pid.get("y_sat", 8.2)), ode_dt=float(ode_dt))


class SimTwoPID:
    """One axis' speed controller exactly as SimTwo computes it (mode ``pidspeed``).

    Per physics step, in the order of ``TFViewer.GLCadencerProgress`` (Viewer.pas 5228-5339):

    1. at a control (script) iteration, SimTwo first sets every axis' ``ref.volts := 0`` and ``ref.w := 0``
       (Viewer.pas 5255-5260), then runs the script, which sets ``ref.w`` (``SetAxisSpeedRef``) and may call
       ``SetMotorControllerState`` / ``SetMotorControllerPars`` (both set ``Sek := 0``,
       ODERobotsPublished.pas 1785-1794, 1814-1820): :meth:`script_cycle`;
    2. ``AxisTorqueModel`` (Viewer.pas 4568-4603): if the controller is active, ``ticks += Ode_dt`` and when
       ``ticks >= ControlPeriod``: ``ticks -= ControlPeriod`` and ``ref.volts := CalcPID(ref.w, ref.w - w)``;
       the motor then gets ``clamp(ref.volts, -Vmax, Vmax)`` this step (held between controller runs):
       :meth:`tick`;
    3. ``CalcPID`` (Viewer.pas 528-546)::

           dek := (ek - ek_1) / Ode_dt;   Sek := Sek + ek * Ode_dt
           mk  := Kp*ek + Ki*Sek + Kd*dek + Kf*ref
           if |mk| >= y_sat: Sek := Sek - ek*Ode_dt; mk := clamp(mk, -y_sat, y_sat)
           ek_1 := ek

    Consequences: Ki acts per Ode_dt (1 ms) of error although the controller runs every 10 ms, i.e. an
    effective integral gain of Ki*Ode_dt/period per second; Kd sees the change of the error over 10 ms
    divided by 1 ms; and after each script iteration the motor gets 0 V until the controller's next run
    (up to period - Ode_dt, depending on the phase of ``ticks``, which counts only while active).
    Floats are updated with the same operations as SimTwo's doubles, so ``ticks`` drifts as SimTwo's does.
    """

    __slots__ = ("p", "active", "sek", "ek_1", "ticks", "ref_w", "ref_volts", "runs")

    def __init__(self, params: SimTwoPIDParams):
        self.p = params
        self.active = False
        self.sek = 0.0  # sum of ek * Ode_dt (rad)
        self.ek_1 = 0.0  # the error at the previous run (rad/s)
        self.ticks = 0.0  # s since the last run (counts only while active)
        self.ref_w = 0.0  # rad/s (SetAxisSpeedRef)
        self.ref_volts = 0.0  # V, the controller's output (or SetAxisVoltageRef)
        self.runs = 0

    def reset(self) -> None:
        """Integral, last error and output to 0 (the simulator's ``set_pose``); ``ticks`` keeps its phase."""
        self.sek = self.ek_1 = self.ref_w = self.ref_volts = 0.0

    def set_state(self, active: bool) -> None:
        """``SetMotorControllerState``: sets ``active`` and resets the integral (``Sek := 0``)."""
        self.active = bool(active)
        self.sek = 0.0

    def set_pars(self, params: SimTwoPIDParams) -> None:
        """``SetMotorControllerPars``: new gains, ``Sek := 0``."""
        self.p = params
        self.sek = 0.0

    def calc(self, ref: float, ek: float) -> float:
        """``CalcPID(PID, ref, ek)``: the controller's output (V)."""
        if not self.active:
            return 0.0
        p = self.p
        dt = p.ode_dt
        dek = (ek - self.ek_1) / dt
        self.sek = self.sek + ek * dt
        mk = p.kp * ek + p.ki * self.sek + p.kd * dek + p.kf * ref
        if abs(mk) >= p.y_sat:
            self.sek = self.sek - ek * dt
            mk = max(-p.y_sat, min(p.y_sat, mk))
        self.ek_1 = ek
        return mk

    def script_cycle(self, ref_w: float, reset_integral: bool = False, hold_voltage: bool = False) -> None:
        """A control (script) iteration: SimTwo zeroes ``ref.volts``; the script sets ``ref.w``, with
        ``reset_integral`` calls ``SetMotorControllerState(.., true)`` (integral to 0) and with
        ``hold_voltage`` puts the controller's last output back (``SetAxisVoltageRef(GetAxisU)``)."""
        if not hold_voltage:
            self.ref_volts = 0.0
        self.ref_w = ref_w
        if reset_integral:
            self.set_state(True)

    def tick(self, w: float) -> float:
        """One physics step's controller part of ``AxisTorqueModel`` at axis speed ``w`` (rad/s); returns
        ``ref.volts`` (before the motor's own +-Vmax clamp)."""
        if self.active:
            self.ticks = self.ticks + self.p.ode_dt
            if self.ticks >= self.p.period:
                self.ticks = self.ticks - self.p.period
                self.ref_volts = self.calc(self.ref_w, self.ref_w - w)
                self.runs += 1
        return self.ref_volts
