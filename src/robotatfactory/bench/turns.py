"""``raf bench turns``: how far the robot really turns against what its odometry says, with and without a part
on the magnet: the measurement behind the EKF's carrying model (``ekf.carry_turn_sigma_per_sqrt_rad``,
docs/localization.md "Turning with a part").

**Mode**: the stand-in's :class:`~robotatfactory.sim.Simulator` in this process (no ROS, no bridge), its
SimTwo-like defaults (SimTwo's speed controller and PID timing, the force magnet), stepped in lockstep (each
command runs in the next control cycle), camera and LIDAR off. Odometry is the encoders' totals through
:class:`~robotatfactory.localization.odometry.DiffDriveOdometry` over the robot file's odometry track, as the
bridge integrates them. A part is held by putting it 4 mm in front of the magnet's face, plate towards it,
and switching the magnet on at rest for 0.8 s (it is pulled against the face), the robot then keeps the magnet
on; "empty" runs have no part and the magnet off.

Scripted manoeuvres, on the default field's floor without its fixtures (``boxes`` removed: the floor's
friction is one plane everywhere, so nothing is hit), from rest, ramped within the agent's limits
(:class:`~robotatfactory.agent.follower.DriveLimits` from the robot file, and ``carry.*`` while carrying:
alpha 6 rad/s^2, a 0.8 m/s^2), 1 s at rest after each:

- ``spin``: turns on the spot by 90 and 180 deg at each rate of :data:`RATES`, both ways, from four headings:
  the truth's turn over the odometry's (mean, sd, min, max);
- ``spin_drive``: the agent's turn -> drive: a quarter turn at W whose rate ramps down while the robot speeds up
  to V (0.2, 0.4 m/s), 0.25 m: the truth's turn minus the odometry's, along the spin (deg; both ways, averaged);
- ``agent_turn``: :data:`AGENT_CARRY_TURN`, the agent's turn with a part as traced (167 deg, driving off with
  the heading feedback turning back, then a bend), the same figure;
- ``arc``: 1.5 rad of heading on arcs (V, W) of :data:`ARCS`: the truth's turn over the odometry's;
- ``straight``: 0.3 m at 0.2 and 0.4 m/s, forwards and backwards: the truth's distance over the odometry's.

**The agent's own turns** (``--rounds``, ``--seeds``): the competition agent plays rounds on the bare stand-in
with ground truth as its pose (as ``raf experiment competition --mode bare_truth``) and every cycle is kept;
round 1 once (its draw is all blue whatever the seed), rounds 2 and 3 with seeds 0..N-1.
A turning episode runs from a cycle whose commanded |w| exceeds 0.05 rad/s to 10 cycles after the last such
cycle (the turn's end and the slip after it), cut short where the next turn begins; episodes whose odometry
turns less than 0.2 rad are left out. Carrying: the magnet commanded on through the episode (the robot's own
command, as the localization node learns it); mixed episodes are left out. Per episode: the truth's turn minus
the odometry's along the turn (deg), and the heading NEES of an EKF started at the truth with no uncertainty and
fed only the episode's odometry (e^2 / P_theta, 1 degree of freedom: 1 on average and above 3.84 in 5 % of the
episodes when its process noise is right), with the default EkfConfig, without the carrying model
(``carry_turn_sigma_per_sqrt_rad`` 0), and the carrying sigma that makes the carrying episodes' mean NEES 1.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

NAME = "turns"
HELP = ("turns on the spot, turn -> drive, arcs and straights with and without a part on the magnet, and the "
        "agent's own turns, on the bare stand-in: the truth's turn against the odometry's (the EKF's carrying "
        "model)")
TARGETS = {"agent_carry_nees_mean": "about 1 (the EKF's heading noise while carrying is right)",
           "agent_empty_nees_mean": "about 1"}
RATES = (0.5, 1.1, 1.5, 3.0)  # rad/s: slow (the drive bench's), carry.w_long_spin, carry.w_max, the empty w_max
SPIN_DRIVE = ((1.1, 0.2), (1.5, 0.2), (1.1, 0.4), (1.5, 0.4), (3.0, 0.4))  # (W rad/s, V m/s)
ARCS = ((0.2, 0.5), (0.2, 1.0), (0.4, 1.0), (0.4, 1.5))  # (V m/s, W rad/s): within carry.w_max, v_max, a_lat
HEADINGS = (0.0, math.pi / 2, math.pi, -math.pi / 2)
PART_GAP_M = 0.004  # the part's plate this far in front of the magnet's face at the start: pulled in at once
EPISODE_W = 0.05  # rad/s: a commanded turn rate above this is turning
EPISODE_TAIL = 10  # cycles after a turn that still belong to it
EPISODE_MIN_TURN = 0.2  # rad
NEES_95 = 3.841  # chi-square, 1 dof, 95 %


@dataclass
class Track:
    """Per control cycle (the first row: the state before the manoeuvre): time (s), encoder totals (left,
    right), the truth (x, y, theta), the commanded (v, w) and magnet."""

    t: np.ndarray
    enc: np.ndarray
    truth: np.ndarray
    cmd: np.ndarray
    magnet: np.ndarray

    def odometry(self, robot) -> np.ndarray:
        """The odometry's pose per row (odom frame, from the first row), heading unwrapped."""
        from ..localization.odometry import DiffDriveOdometry

        odo = DiffDriveOdometry(robot)
        out = []
        for (el, er), t in zip(self.enc, self.t):
            s = odo.update(int(el), int(er), float(t))
            out.append((s.x, s.y, s.theta))
        a = np.array(out)
        a[:, 2] = np.unwrap(a[:, 2])
        return a

    def truth_yaw(self) -> np.ndarray:
        return np.unwrap(self.truth[:, 2])


def open_floor(field):
    """The field without its boxes: the same floor, nothing to hit."""
    return replace(field, boxes=())


def make_sim(field, robot, pose, carry: bool):
    """A Simulator at ``pose`` (x, y, theta); with ``carry`` a part held on the magnet (pulled in at rest)."""
    from ..sim import PartPlacement, SimConfig, Simulator
    from ..simtwo import Command

    extra = ()
    if carry:
        d = float(robot.electromagnet["x"]) + field.part.depth / 2 + PART_GAP_M
        x, y, th = pose
        extra = (PartPlacement("R", x + d * math.cos(th), y + d * math.sin(th), th + math.pi),)
    sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False, start_pose=tuple(pose),
                                            extra_parts=extra))
    for _ in range(20):
        sim.step_cycle(Command(0.0, 0.0, carry))
    if carry and sim.held is None:
        sim.close()
        raise RuntimeError(f"the part at {pose} was not pulled onto the magnet")
    return sim


def drive(sim, commands, magnet: bool, rest: int = 25) -> Track:
    """Run (v, w) commands, then ``rest`` cycles at rest; the cycles as a :class:`Track`."""
    from ..simtwo import Command

    f = sim.step_cycle(Command(0.0, 0.0, magnet))
    rows = [(f.time, *f.enc_total, f.x, f.y, f.theta, 0.0, 0.0, magnet)]
    for v, w in list(commands) + [(0.0, 0.0)] * rest:
        f = sim.step_cycle(Command(v, w, magnet))
        rows.append((f.time, *f.enc_total, f.x, f.y, f.theta, v, w, magnet))
    a = np.array(rows, dtype=float)
    return Track(a[:, 0], a[:, 1:3], a[:, 3:6], a[:, 6:8], a[:, 8] > 0.5)


def ramp(v0: float, w0: float, v1: float, w1: float, a: float, alpha: float, hold: int = 0,
         dt: float = 0.04) -> list[tuple[float, float]]:
    """Commands from (v0, w0) to (v1, w1) within the accelerations, then ``hold`` cycles at (v1, w1)."""
    out, v, w = [], v0, w0
    while abs(v - v1) > 1e-9 or abs(w - w1) > 1e-9:
        v += max(-a * dt, min(a * dt, v1 - v))
        w += max(-alpha * dt, min(alpha * dt, w1 - w))
        out.append((v, w))
    return out + [(v1, w1)] * hold


def spin(w: float, angle: float, alpha: float, dt: float = 0.04) -> list[tuple[float, float]]:
    """A turn on the spot by ``angle`` (rad, > 0) at up to |w| (its sign: the direction), ramped at alpha."""
    out, cur, done, s = [], 0.0, 0.0, math.copysign(1.0, w)
    while True:
        if cur > 0 and done + cur * cur / (2 * alpha) >= angle - 1e-9:
            cur = max(0.0, cur - alpha * dt)
        else:
            cur = min(abs(w), cur + alpha * dt)
        out.append((0.0, s * cur))
        done += cur * dt
        if cur == 0.0:
            return out


def spin_then_drive(w: float, v: float, a: float, alpha: float, angle: float = math.pi / 2,
                    distance: float = 0.25, correction: tuple[float, int] = (0.0, 0),
                    arc: tuple[float, int] = (0.0, 0), dt: float = 0.04) -> list[tuple[float, float]]:
    """The follower's turn -> drive: a turn on the spot by ``angle`` (rad) at up to |w| (its sign: the direction)
    whose turn rate ramps down (alpha) while the speed ramps up towards v (a), as the agent drives off once the
    heading is within tolerance; ``correction`` (|w| rad/s, cycles): the heading feedback then turns back against
    the overshoot so long; ``arc`` (|w| rad/s, cycles): then an arc the original way so long (the path's next
    bend); then straight on until ``distance`` (m) is driven, and braking to rest."""
    sp = spin(w, angle, alpha, dt)
    k = next(j for j in range(1, len(sp)) if abs(sp[j][1]) < abs(sp[j - 1][1]))  # the turn starts to end
    out, s = list(sp[:k]), math.copysign(1.0, w)
    v_now, w_now, d = 0.0, sp[k - 1][1], 0.0

    def to(w_target: float, hold: int) -> None:
        nonlocal v_now, w_now, d
        n = 0
        while abs(w_now - w_target) > 1e-9 or n < hold:
            if abs(w_now - w_target) <= 1e-9:
                n += 1
            v_now = min(v, v_now + a * dt)
            w_now += max(-alpha * dt, min(alpha * dt, w_target - w_now))
            out.append((v_now, w_now))
            d += v_now * dt

    if correction[1]:
        to(-s * correction[0], correction[1])
    if arc[1]:
        to(s * arc[0], arc[1])
    to(0.0, 0)
    while d + v_now * v_now / (2 * a) < distance:
        to(0.0, 1)
    return out + ramp(v_now, 0.0, 0.0, 0.0, a, alpha)


#: the agent's turn with a part at its limits as traced in round 3 (seed 1, 16.0-19.1 s, bare stand-in): 167 deg
#: on the spot at carry.w_max, driving off towards carry.v_max with the heading feedback turning back at 0.45 rad/s
#: for 0.24 s, then the path's bend at 1.2 rad/s for 0.48 s (its odometry missed 9 deg of the truth's turn)
AGENT_CARRY_TURN = dict(w=1.5, v=0.4, angle=math.radians(167), distance=0.45, correction=(0.45, 6), arc=(1.2, 12))


def agent_limits(robot, carry: bool) -> tuple[float, float]:
    """(a, alpha): the agent's accelerations, its carrying ones with a part."""
    from ..agent.follower import DriveLimits
    from ..agent.settings import Carrying

    lim = DriveLimits.from_robot(robot)
    c = Carrying()
    return lim.a_max, (c.alpha_max if carry and c.alpha_max > 0 else lim.alpha_max)


def _stats(prefix: str, vals) -> dict:
    a = np.asarray(vals, dtype=float)
    return {f"{prefix}_mean": float(a.mean()), f"{prefix}_sd": float(a.std(ddof=1)) if len(a) > 1 else 0.0,
            f"{prefix}_min": float(a.min()), f"{prefix}_max": float(a.max())}


def _label(carry: bool) -> str:
    return "carry" if carry else "empty"


def scripted(field, robot) -> dict:
    """The scripted manoeuvres' figures (module docstring)."""
    floor = open_floor(field)
    out = {}
    for carry in (False, True):
        a, alpha = agent_limits(robot, carry)
        lab = _label(carry)
        for w in RATES:
            ratios = []
            for angle in (math.pi / 2, math.pi):
                for h in HEADINGS:
                    for sgn in (1, -1):
                        sim = make_sim(floor, robot, (0.0, 0.0, h), carry)
                        tr = drive(sim, spin(sgn * w, angle, alpha), carry)
                        sim.close()
                        odo = tr.odometry(robot)[:, 2]
                        ratios.append((tr.truth_yaw()[-1] - tr.truth_yaw()[0]) / (odo[-1] - odo[0]))
            out.update(_stats(f"spin_{lab}_w{w:g}_truth_over_odom", ratios))
        plans = [(f"spin_drive_{lab}_w{w:g}_v{v:g}", dict(w=w, v=v)) for w, v in SPIN_DRIVE]
        plans.append((f"agent_turn_{lab}", AGENT_CARRY_TURN))
        for key, plan in plans:
            excess = []
            for sgn in (1, -1):  # (the open floor: the heading does not matter)
                sim = make_sim(floor, robot, (0.0, 0.0, 0.0), carry)
                tr = drive(sim, spin_then_drive(**{**plan, "w": sgn * plan["w"], "a": a, "alpha": alpha}), carry)
                sim.close()
                odo = tr.odometry(robot)[:, 2]
                ty = tr.truth_yaw()
                excess.append(sgn * math.degrees((ty[-1] - ty[0]) - (odo[-1] - odo[0])))
            out[f"{key}_truth_minus_odom_deg"] = float(np.mean(excess))
        for v, w in ARCS:
            ratios = []
            for h in HEADINGS[:2]:
                for sgn in (1, -1):
                    sim = make_sim(floor, robot, (0.0, 0.0, h), carry)
                    up = ramp(0.0, 0.0, v, sgn * w, a, alpha)
                    turned = sum(abs(c[1]) for c in up) * 0.04
                    hold = max(0, int((1.5 - 2 * turned) / w / 0.04))
                    cmds = up + [(v, sgn * w)] * hold + ramp(v, sgn * w, 0.0, 0.0, a, alpha)
                    tr = drive(sim, cmds, carry)
                    sim.close()
                    odo = tr.odometry(robot)[:, 2]
                    ratios.append((tr.truth_yaw()[-1] - tr.truth_yaw()[0]) / (odo[-1] - odo[0]))
            out.update(_stats(f"arc_{lab}_v{v:g}_w{w:g}_truth_over_odom", ratios))
        for v in (0.2, 0.4):  # (deterministic and straight: one run each way)
            for sgn, way in ((1, "forwards"), (-1, "backwards")):
                sim = make_sim(floor, robot, (0.0, 0.0, 0.0), carry)
                up = ramp(0.0, 0.0, sgn * v, 0.0, a, alpha)
                hold = max(0, int((0.3 - 2 * sum(abs(c[0]) for c in up) * 0.04) / v / 0.04))
                tr = drive(sim, up + [(sgn * v, 0.0)] * hold + ramp(sgn * v, 0.0, 0.0, 0.0, a, alpha), carry)
                sim.close()
                o = tr.odometry(robot)
                key = f"straight_{lab}_v{v:g}_{way}"
                out[f"{key}_truth_over_odom"] = math.dist(tr.truth[-1, :2], tr.truth[0, :2]) / math.hypot(*o[-1, :2])
                out[f"{key}_truth_minus_odom_turn_deg"] = math.degrees(tr.truth_yaw()[-1] - tr.truth_yaw()[0]
                                                                       - o[-1, 2])
    return out


# ------------------------------------------------------------------------------------------ the agent's turns
def agent_track(round_no: int, seed: int, limit: float = 300.0, agent: dict | None = None) -> Track:
    """One round of the competition agent on the bare stand-in, ground truth as its pose (``raf experiment
    competition --mode bare_truth``'s loop, :func:`~..experiments.competition.play_round`, without pose noise or
    delays), every cycle kept."""
    from ..experiments.competition import play_round

    rows = []

    def keep(sim, agent, c, f) -> None:
        rows.append((f.time, *f.enc_total, f.x, f.y, f.theta, c.v, c.w, bool(c.magnet)))

    play_round(round_no, seed, limit, agent=agent, after_cycle=keep)
    a = np.array(rows, dtype=float)
    return Track(a[:, 0], a[:, 1:3], a[:, 3:6], a[:, 6:8], a[:, 8] > 0.5)


@dataclass(frozen=True)
class Episode:
    """One turn of a track: rows [i - 1, k) (row i - 1: the state before it)."""

    i: int
    k: int
    carrying: bool | None  # None: the magnet switched during it


def episodes(track: Track) -> list[Episode]:
    """The turning episodes of a track (module docstring)."""
    w = np.abs(track.cmd[:, 1]) > EPISODE_W
    n, out, i = len(w), [], 1
    while i < n:
        if not w[i]:
            i += 1
            continue
        j = i
        while j < n and w[j]:
            j += 1
        k = min(n, j + EPISODE_TAIL)
        nxt = np.flatnonzero(w[j:k])
        k = j + int(nxt[0]) if len(nxt) else k
        m = track.magnet[i - 1:k]
        out.append(Episode(i, k, bool(m[0]) if m.all() or not m.any() else None))
        i = k
    return out


def episode_errors(track: Track, robot, cfgs: dict) -> list[dict]:
    """Per episode: the odometry's turn (rad), the truth's minus the odometry's along it (rad), and per EKF
    setting in ``cfgs`` ({name: EkfConfig}) the heading NEES of the filter fed the episode's odometry."""
    from ..localization.ekf import Ekf

    odo = track.odometry(robot)
    ty = track.truth_yaw()
    out = []
    for ep in episodes(track):
        turn = odo[ep.k - 1, 2] - odo[ep.i - 1, 2]
        if ep.carrying is None or abs(turn) < EPISODE_MIN_TURN:
            continue
        err = (ty[ep.k - 1] - ty[ep.i - 1]) - turn
        row = {"carrying": ep.carrying, "turn": turn, "along": math.copysign(1.0, turn) * err,
               "turned": float(np.abs(np.diff(odo[ep.i - 1:ep.k, 2])).sum())}
        for name, cfg in cfgs.items():
            ekf = Ekf(cfg)
            ekf.set_carrying(track.t[ep.i - 1], ep.carrying)
            ekf.initialise(track.t[ep.i - 1], tuple(track.truth[ep.i - 1]), np.diag([1e-12, 1e-12, 1e-12]))
            for q in range(ep.i - 1, ep.k):
                ekf.odometry_pose(track.t[q], tuple(odo[q]))
            e = math.remainder(track.truth[ep.k - 1, 2] - ekf.pose()[2], 2 * math.pi)
            row[f"nees_{name}"] = e * e / ekf.covariance()[2, 2]
            row[f"var_{name}"] = ekf.covariance()[2, 2]
        out.append(row)
    return out


def fit_carry_sigma(rows: list[dict], var_key: str) -> float:
    """The carrying turn sigma (rad per sqrt(rad)) that makes the mean heading NEES of ``rows`` 1, added to the
    variances ``rows[var_key]`` of a filter without it (bisection; 0 when they are already consistent)."""
    e2 = np.array([r["along"] ** 2 for r in rows])
    v = np.array([r[var_key] for r in rows])
    tu = np.array([r["turned"] for r in rows])
    if not len(rows) or np.mean(e2 / v) <= 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    for _ in range(60):
        k = (lo + hi) / 2
        lo, hi = (k, hi) if np.mean(e2 / (v + k * k * tu)) > 1.0 else (lo, k)
    return (lo + hi) / 2


def agent_figures(robot, rounds, seeds, agent: dict | None = None) -> dict:
    from ..localization.ekf import EkfConfig

    base = EkfConfig(track_m=robot.odometry_track)
    cfgs = {"model": base, "nomodel": replace(base, carry_turn_sigma_per_sqrt_rad=0.0)}
    rows, runs = [], [(r, s) for r in rounds for s in (seeds[:1] if r == 1 else seeds)]
    for r, s in runs:
        print(f"[bench turns] the agent: round {r}, seed {s}", flush=True)
        rows += episode_errors(agent_track(r, s, agent=agent), robot, cfgs)
    out = {"agent_runs": len(runs)}
    for carry in (False, True):
        sel = [x for x in rows if x["carrying"] == carry]
        lab = _label(carry)
        out[f"agent_{lab}_episodes"] = len(sel)
        if not sel:
            continue
        along = np.degrees([x["along"] for x in sel])
        out[f"agent_{lab}_turn_rad_median"] = float(np.median([abs(x["turn"]) for x in sel]))
        out[f"agent_{lab}_truth_minus_odom_deg_mean"] = float(along.mean())
        out[f"agent_{lab}_truth_minus_odom_deg_sd"] = float(along.std(ddof=1))
        out[f"agent_{lab}_truth_minus_odom_deg_p95abs"] = float(np.percentile(np.abs(along), 95))
        turns = np.abs([x["turn"] for x in sel])
        out[f"agent_{lab}_truth_over_odom"] = float((turns + np.radians(along)).sum() / turns.sum())
        for name in cfgs:
            nees = np.array([x[f"nees_{name}"] for x in sel])
            key = "nees" if name == "model" else "nees_without_carry_model"
            out[f"agent_{lab}_{key}_mean"] = float(nees.mean())
            out[f"agent_{lab}_{key}_over_3.84_share"] = float(np.mean(nees > NEES_95))
        if carry:
            out["agent_carry_fit_sigma_per_sqrt_rad"] = fit_carry_sigma(sel, "var_nomodel")
    return out


# ------------------------------------------------------------------------------------------ the command
def add_arguments(parser) -> None:
    parser.add_argument("--rounds", default="1,2,3", help="the agent's rounds (default 1,2,3; empty: none)")
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 of rounds 2 and 3 (round 1: once, its "
                                                              "draw does not depend on the seed; default 10)")
    parser.add_argument("--no-scripted", action="store_true", help="only the agent's turns")
    parser.add_argument("--agent", metavar="NAME=VALUE", action="append", default=[],
                        help="an agent setting for the agent's rounds (as raf experiment competition's --agent), e.g. "
                             "carry.spin_settle=0 (repeatable)")


def run(args) -> dict:
    from ..field import load_field
    from ..robot import load_robot

    field, robot = load_field(), load_robot()
    out = {"mode": "stand-in Simulator in process, SimTwo-like defaults, lockstep, no camera/LIDAR",
           "odometry_track_m": robot.odometry_track}
    if not args.no_scripted:
        print("[bench turns] scripted manoeuvres", flush=True)
        out.update(scripted(field, robot))
    from ..experiments.competition import parse_agent

    agent = parse_agent(getattr(args, "agent", None))
    rounds = [int(r) for r in str(args.rounds).split(",") if r.strip()]
    if rounds and args.seeds > 0:
        if agent:
            out["agent_settings"] = ",".join(getattr(args, "agent"))
        out.update(agent_figures(robot, rounds, list(range(args.seeds)), agent))
    return out
