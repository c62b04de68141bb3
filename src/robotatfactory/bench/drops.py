"""``raf bench drops``: the agent finding and picking up again a part knocked off its magnet (issue 20 item 5,
docs/agent.md "A part dropped on the floor").

**Mode**: the bare stand-in in this process (:func:`~robotatfactory.experiments.competition.play_round`: the
competition agent on ground truth as its pose, SimTwo-like defaults, SimTwo's force magnet), the LIDAR on (the
agent gets each sweep as the bridge stamps it). Rounds ``--rounds`` x seeds ``0..--seeds-1``. In each run, a
draw per run (seeded) of 0.6-2.5 s after the first pick the carried part is put at rest on free floor 13-17 cm
to one side of the magnet (the other side when that one is not free), turned by up to 0.8 rad
(``Simulator.place_part``): the part is lost as if knocked off. Each run is played twice: with the recovery
(``recovery.refind``, the default) and without it. Per way: runs at the maximum, points, and with the recovery
the seconds from the loss to the re-pick and the rounds' delay against an undisturbed run of the same seed.
"""
from __future__ import annotations

import math
import random
import statistics

NAME = "drops"
HELP = ("parts knocked off the magnet on the bare stand-in (LIDAR on): runs at the maximum and points with and "
        "without the agent's recovery (recovery.refind), seconds from the loss to the re-pick")
TARGETS = {"refind_max_score_runs": "more than without the recovery (refind_off_max_score_runs)"}


class KnockOff:
    """The ``on_cycle`` hook of one run: knocks the carried part off once, ``after`` s after the first pick: it comes
    to rest ``lateral`` m to the robot's left (``side`` 1) or right (-1) of where it was held, turned by ``turn``
    rad (the simulator's place_part: off the magnet, at rest on the floor). Where that spot is not free floor it
    tries the other side, then waits for the next pick (``fallback`` False: neither, it knocks nothing)."""

    def __init__(self, field, robot, after: float, side: int, lateral: float, turn: float, fallback: bool = True):
        from ..agent.footprint import robot_footprint

        self.field, self.fp, self.magnet_x = field, robot_footprint(robot), float(robot.electromagnet["x"])
        self.after, self.side, self.lateral, self.turn = float(after), int(side), float(lateral), float(turn)
        self.fallback = fallback
        self.picked_t: float | None = None
        self.t: float | None = None  # when it was knocked off
        self.pid: int | None = None  # ... which part
        self.at: tuple[float, float] | None = None  # ... and where it came to rest
        self.refused: float | None = None  # when it gave up (fallback False): the spot was not free floor

    @classmethod
    def drawn(cls, field, robot, seed: int) -> KnockOff:
        """The bench's seeded knock: 0.6-2.5 s after the pick, 13-17 cm to either side, turned up to 0.8 rad."""
        rng = random.Random(seed)
        after, side = rng.uniform(0.6, 2.5), rng.choice((-1, 1))
        return cls(field, robot, after, side, rng.uniform(0.13, 0.17), rng.uniform(-0.8, 0.8))

    def __call__(self, sim, agent) -> None:
        if self.t is not None or self.refused is not None or agent.mode != "to_place" or sim.held is None:
            return
        if self.picked_t is None:
            self.picked_t = sim.time
        if sim.time - self.picked_t < self.after:
            return
        from ..agent.refind import lost_spot

        th = sim.pose[2]
        pid = sim.held
        held = lost_spot(sim.pose, self.magnet_x, self.field.part)  # the held part's centre
        for side in ((self.side, -self.side) if self.fallback else (self.side,)):
            px = held.x - side * self.lateral * math.sin(th)
            py = held.y + side * self.lateral * math.cos(th)
            facing = th + math.pi + self.turn
            if self._free(sim, pid, px, py, facing):
                sim.place_part(pid, px, py, facing)
                self.t, self.pid, self.at = sim.time, pid, (px, py)
                return
        if self.fallback:
            self.picked_t = None  # no free floor there: after the next pick
        else:
            self.refused = sim.time  # not knocked: its spot was not free floor

    def _free(self, sim, pid, px, py, facing) -> bool:
        """On the floor, clear of the fixtures, the other parts and the robot."""
        from ..agent.obstacles import FieldObstacles, PartObstacle, part_polygon, polygons_overlap

        others = FieldObstacles(self.field, [PartObstacle(*sim.part_pose(q)) for q in sim.parts.ids if q != pid])
        poly = part_polygon(self.field.part, PartObstacle(px, py, facing))
        (x0, x1), (y0, y1) = self.field.floor.x, self.field.floor.y
        if poly[:, 0].min() < x0 or poly[:, 0].max() > x1 or poly[:, 1].min() < y0 or poly[:, 1].max() > y1:
            return False
        return not (any(polygons_overlap(poly, p) for p in others.polygons)
                    or any(polygons_overlap(poly, p) for p in self.fp.polygons(*sim.pose)))


def add_arguments(parser) -> None:
    parser.add_argument("--rounds", default="1,2,3", help="rounds (default 1,2,3)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 of each round (default 5)")


def run(args) -> dict:
    from ..experiments.competition import play_round
    from ..field import load_field
    from ..robot import load_robot

    field, robot = load_field(), load_robot()
    rounds = [int(r) for r in str(args.rounds).split(",") if r.strip()]
    out: dict = {"mode": "stand-in Simulator in process, SimTwo-like defaults, force magnet, ground truth as the "
                         "pose, LIDAR on; the carried part put 13-17 cm to the side once, 0.6-2.5 s after the first pick"}
    ways = {"refind": {}, "refind_off": {"recovery": {"refind": False}}}
    rows = {k: [] for k in ways}
    repick, delay = [], []
    for rnd in rounds:
        for seed in range(args.seeds):
            base = play_round(rnd, seed, lidar=True)
            for way, agent in ways.items():
                hook = KnockOff.drawn(field, robot, seed * 10 + rnd)
                r = play_round(rnd, seed, record_path=True, agent=agent, lidar=True, on_cycle=hook)
                rows[way].append(r)
                ev = r.get("events", [])
                lost = next((t for t, e, *_ in ev if e.startswith("lost the")), None)
                again = next((t for t, e, *_ in ev if e.startswith("picked the lost")), None)
                if way == "refind" and lost is not None and again is not None:
                    repick.append(again - lost)
                if way == "refind" and r["max_score"] and base["max_score"]:
                    delay.append(r["last_score_s"] - base["last_score_s"])
                print(f"[bench drops] round {rnd} seed {seed} {way}: knocked off at "
                      f"{'-' if hook.t is None else f'{hook.t:.2f} s'}, {r['points']} of {r['max_points']} points",
                      flush=True)
    for way, rr in rows.items():
        out[f"{way}_runs"] = len(rr)
        out[f"{way}_max_score_runs"] = sum(bool(r["max_score"]) for r in rr)
        out[f"{way}_points"] = sum(r["points"] for r in rr)
        out[f"{way}_max_points"] = sum(r["max_points"] for r in rr)
        out[f"{way}_collision_checks_hit"] = sum(r.get("collision_checks_hit", 0) or 0 for r in rr)
    out["refind_loss_to_repick_median_s"] = statistics.median(repick) if repick else math.nan
    out["refind_loss_to_repick_max_s"] = max(repick) if repick else math.nan
    out["refind_delay_vs_undisturbed_median_s"] = statistics.median(delay) if delay else math.nan
    out["refind_delay_vs_undisturbed_max_s"] = max(delay) if delay else math.nan
    return out
