"""``raf experiment envelope``: which drives keep a part on the stand-in's electromagnet (SimTwo's force by
default).

A robot at the origin heading +x holds a part whose plate touches its magnet; each trial drives a ramped
profile (turn on the spot, arc forwards or backwards, straight) and reports whether the part was lost
(``Simulator.held`` went None) and how far it slid sideways on the magnet's face (m). Plain Python on the
bare stand-in (no ROS): the table docs/agent.md and docs/simulator.md quote. An experiment, not part of the
agent: the agent's carrying limits were chosen from it (docs/agent.md, "The carry envelope").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

NAME = "envelope"
HELP = ("the carry envelope: which ramped turns, arcs and straights keep a part on the stand-in's magnet, and "
        "how far it slides on the face")
TARGETS: dict = {}


def touch_distance(robot, part) -> float:
    """base_link to the centre of a part whose plate touches the magnet (m)."""
    from ..agent.footprint import dock_distance

    return dock_distance(robot, part, gap=0.0)


@dataclass(frozen=True)
class Trial:
    kind: str  # "spin", "arc", "straight"
    v: float  # m/s (negative: backwards)
    w: float  # rad/s
    a: float  # m/s^2
    alpha: float  # rad/s^2
    turn: float = math.pi / 2  # rad turned (spin, arc) at the target rates
    hold: int = 0  # straight: cycles at speed


def ramp(v0, w0, v1, w1, a, alpha, dt=0.04):
    out, v, w = [], v0, w0
    while abs(v - v1) > 1e-9 or abs(w - w1) > 1e-9:
        v += max(-a * dt, min(a * dt, v1 - v))
        w += max(-alpha * dt, min(alpha * dt, w1 - w))
        out.append((v, w))
    return out


def profile(t: Trial, dt=0.04):
    if t.kind == "straight":
        return ramp(0, 0, t.v, 0, t.a, t.alpha, dt) + [(t.v, 0.0)] * t.hold + ramp(t.v, 0, 0, 0, t.a, t.alpha, dt)
    up = ramp(0, 0, t.v, t.w, t.a, t.alpha, dt)
    down = ramp(t.v, t.w, 0, 0, t.a, t.alpha, dt)
    turned = sum(abs(w) for _, w in up + down) * dt
    n = max(0, int(round((t.turn - turned) / max(abs(t.w) * dt, 1e-9))))
    return up + [(t.v, t.w)] * n + down


def run_trial(field, robot, t: Trial, magnet: str | None = None, settle: int = 5) -> tuple[bool, float]:
    """(held to the end, largest sideways slide on the face in m)."""
    from ..sim import PartPlacement, SimConfig, Simulator
    from ..simtwo import Command

    part = PartPlacement("R", touch_distance(robot, field.part) + 0.002, 0.0, math.pi)
    magnet = magnet or SimConfig.magnet
    sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False, magnet=magnet,
                                            start_pose=(0.0, 0.0, 0.0), extra_parts=(part,)))
    try:
        for _ in range(settle):
            sim.step_cycle(Command(0.0, 0.0, True))
        pid = sim.parts.ids[0]
        worst, held = 0.0, sim.held is not None
        for v, w in profile(t) + [(0.0, 0.0)] * 5:
            sim.step_cycle(Command(v, w, True))
            x, y, th = sim.pose
            px, py, _ = sim.part_pose(pid)
            lat = -math.sin(th) * (px - x) + math.cos(th) * (py - y)
            worst = max(worst, abs(lat))
            held = held and sim.held is not None
        return held, worst
    finally:
        sim.close()


def default_trials() -> list[Trial]:
    out = []
    for w in (0.5, 1.0, 1.5, 2.0, 2.5, 3.0):
        for alpha in (2.0, 4.0, 6.0, 11.85):
            out.append(Trial("spin", 0.0, w, 0.8, alpha, turn=math.pi))
    for v in (0.2, 0.3, 0.4, -0.2, -0.3):
        for r in (0.1, 0.15, 0.2, 0.3, 0.5):
            w = abs(v) / r
            if w > 4.0:
                continue
            out.append(Trial("arc", v, w, 0.8, 11.85))
    for a in (0.8, 2.0, 4.0):
        out.append(Trial("straight", 0.4, 0.0, a, 11.85, hold=15))
        out.append(Trial("straight", -0.4, 0.0, a, 11.85, hold=15))
    return out


def key(t: Trial) -> str:
    """The trial's prefix in the results: ``spin_w1.5_alpha6``, ``arc_v-0.3_r0.1``, ``straight_v0.4_a2``."""
    def g(v: float) -> str:
        return f"{v:g}"

    if t.kind == "spin":
        return f"spin_w{g(t.w)}_alpha{g(t.alpha)}"
    if t.kind == "arc":
        return f"arc_v{g(t.v)}_r{g(round(abs(t.v / t.w), 3))}"
    return f"straight_v{g(t.v)}_a{g(t.a)}"


def add_arguments(parser) -> None:
    from ..sim.config import MAGNETS, SimConfig

    parser.add_argument("--magnet", default=SimConfig.magnet, choices=MAGNETS,
                        help=f"the stand-in's magnet model (default {SimConfig.magnet}: SimTwo's)")
    parser.add_argument("--kind", default=None, choices=("spin", "arc", "straight"), help="only these trials")


def run(args, out_dir=None) -> dict:
    from ..field import load_field
    from ..robot import load_robot

    field, robot = load_field(), load_robot()
    trials = [t for t in default_trials() if not args.kind or t.kind == args.kind]
    out: dict = {"magnet": args.magnet, "trials": len(trials)}
    lost = 0
    for i, t in enumerate(trials, 1):
        held, slide = run_trial(field, robot, t, args.magnet)
        lost += not held
        out[f"{key(t)}_held"] = held
        out[f"{key(t)}_slide_mm"] = round(slide * 1000, 2)
        print(f"[envelope] {i}/{len(trials)} {key(t)}: {'held' if held else 'LOST'}, slide {slide * 1000:.1f} mm",
              flush=True)
    out["trials_lost"] = lost
    return out
