"""``raf bench looks``: the place after a look at markers before it (docs/agent.md "Going on after the look before
a place").

**Mode**: the bare stand-in in this process (:func:`~robotatfactory.experiments.competition.play_round`: the
competition agent on ground truth as its pose, SimTwo-like defaults, SimTwo's force magnet). Ground truth has no
uncertainty; :class:`UnsureUntilLooked` gives the agent a position std of ``--std`` m on its legs to a place from
the first one until it has looked at markers for ``--look`` s (a large ``--look``: a std that never falls), so that
on the last 15 cm of such a leg it stops, part held, to look (``recovery.place_uncertainty_limit``, 10 mm).
Rounds ``--rounds`` x seeds ``0..--seeds-1``, each played three ways: undisturbed, with the look and the robot
going on along its path after it (``recovery.go_on_after_look``, the default), and with the look and the leg
planned again from where the robot stopped (the behaviour until stop 58). Per way: runs at the maximum, the places
after the look that went in at the first try, places failed, and the seconds from the start of the look to the end
of that place.
"""
from __future__ import annotations

import math
import statistics

NAME = "looks"
HELP = ("a look at markers before a place, provoked on the bare stand-in: the place after it at the first try or "
        "not, going on along the leg's path (recovery.go_on_after_look) and planning the leg again")
TARGETS = {"go_on_first_try_share": "1.0: every place after a look goes in at the first try",
           "go_on_max_score_runs": "all of go_on_runs"}

#: the position std (m) of a sure estimate (the stand-in's whole stack as a place begins: 0.9 mm median, 2.2 max)
SURE = 0.003


class UnsureUntilLooked:
    """The ``uncertainty`` hook of one run (:func:`play_round`): (``std`` m, 0.01 rad) while the agent drives
    to a place or looks at markers, until it has looked for ``look`` s; otherwise, and for the rest of the run,
    (:data:`SURE`, 0.01 rad). ``t0``: when the look began."""

    def __init__(self, std: float, look: float):
        self.std, self.look = float(std), float(look)
        self.t0: float | None = None

    def __call__(self, sim, agent):
        if self.t0 is None and agent.mode == "relocalize":
            self.t0 = sim.time
        if self.t0 is not None and sim.time - self.t0 >= self.look:
            return (SURE, 0.01)
        return (self.std, 0.01) if agent.mode in ("to_place", "relocalize") else (SURE, 0.01)


def after_look(events) -> dict:
    """What followed the first look before a place in a run's ``events`` [(t, text, ...)]: ``looked`` (bool),
    ``first_try`` (the next place event was a place, not a failure), ``place_s`` (from the look's start to that
    place; nan if none)."""
    ev = [(t, text) for t, text, *_ in events]
    t0 = next((t for t, text in ev if text.startswith("pose unsure before the place")), None)
    if t0 is None:
        return {"looked": False, "first_try": False, "place_s": math.nan}
    nxt = next(((t, text) for t, text in ev if t > t0 and text.startswith(("placed ", "place at "))), None)
    first = nxt is not None and nxt[1].startswith("placed ")
    placed = next((t for t, text in ev if t > t0 and text.startswith("placed ")), None)
    return {"looked": True, "first_try": first, "place_s": math.nan if placed is None else placed - t0}


def add_arguments(parser) -> None:
    parser.add_argument("--rounds", default="1,2,3", help="rounds (default 1,2,3)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 of each round (default 5)")
    parser.add_argument("--std", type=float, default=0.015,
                        help="m: the position std on the legs to a place until --look s of looking (default "
                             "0.015; the real SimTwo's one unsure place began at 18.6 mm)")
    parser.add_argument("--look", type=float, default=1.0, help="s of looking before the std is sure (default 1)")


def run(args) -> dict:
    from ..experiments.competition import play_round

    rounds = [int(r) for r in str(args.rounds).split(",") if r.strip()]
    out: dict = {"mode": "stand-in Simulator in process, SimTwo-like defaults, force magnet, ground truth as the "
                         f"pose; a position std of {args.std * 1000:.0f} mm on the legs to a place until "
                         f"{args.look:g} s of looking at markers"}
    ways = {"go_on": {}, "replan": {"recovery": {"go_on_after_look": False}}}
    rows = {k: [] for k in ways}
    delay = {k: [] for k in ways}
    for rnd in rounds:
        for seed in range(args.seeds):
            base = play_round(rnd, seed)
            for way, agent in ways.items():
                r = play_round(rnd, seed, record_path=True, agent=agent,
                               uncertainty=UnsureUntilLooked(args.std, args.look))
                a = after_look(r.get("events", []))
                rows[way].append((r, a))
                if r["max_score"] and base["max_score"]:
                    delay[way].append(r["last_score_s"] - base["last_score_s"])
                print(f"[bench looks] round {rnd} seed {seed} {way}: "
                      f"{'no look' if not a['looked'] else 'placed at the first try' if a['first_try'] else 'place failed'}"
                      f", {r['points']} of {r['max_points']} points", flush=True)
    for way, rr in rows.items():
        looked = [a for _, a in rr if a["looked"]]
        out[f"{way}_runs"] = len(rr)
        out[f"{way}_runs_looked"] = len(looked)
        out[f"{way}_max_score_runs"] = sum(bool(r["max_score"]) for r, _ in rr)
        out[f"{way}_first_try_share"] = (sum(a["first_try"] for a in looked) / len(looked)) if looked else math.nan
        out[f"{way}_place_failures"] = sum(r["place_failures"] for r, _ in rr)
        secs = [a["place_s"] for a in looked if not math.isnan(a["place_s"])]
        out[f"{way}_look_to_placed_median_s"] = statistics.median(secs) if secs else math.nan
        out[f"{way}_look_to_placed_max_s"] = max(secs) if secs else math.nan
        out[f"{way}_delay_vs_undisturbed_median_s"] = statistics.median(delay[way]) if delay[way] else math.nan
    return out
