"""``raf bench simtwo``: the real SimTwo (the Linux build) measured without ROS, over repeated runs.

The first drive of ``raf bench drive`` (:mod:`.drive`, which runs the same drive on either simulator), kept as
it was: settle 2 s, 0.6 m straight at 0.2 m/s, half a turn on the spot at 1.5 rad/s or ``--spin-rate``, 0.5 m
straight, stop; the same figures (rates, SimTwo's clock against the wall clock, the share of cycles in which
SimTwo applied a reply from control.pas's status line, the camera's rate and arrival after the SensorFrame
before it, the LIDAR, odometry against SimTwo's ground truth over the whole drive and per segment). Ranges
are min-max over the runs. ``raf bench drive --simulator simtwo`` drives the longer route (arcs, both spin
rates) on SimTwo.
"""
from __future__ import annotations

import math

from . import drive as _drive
from .drive import STATUS_EVERY  # noqa: F401  (control.pas's status period, as before)

NAME = "simtwo"
HELP = "the real SimTwo on Linux: rates, replies applied, camera, odometry against its ground truth (no ROS)"
TARGETS = {"frames_per_s_sim_median": "25 (SimTwo's 40 ms script period)",
           "replies_applied_share_min": "> 0.95 (patch 15: docs/simtwo.md)"}
SPIN_RATE = 1.5  # rad/s: half a turn on the spot in 2.1 s


def drive(spin_rate: float = SPIN_RATE) -> tuple:
    """The scripted drive: Segments (name, seconds, V m/s, W rad/s); half a turn on the spot at ``spin_rate``."""
    S = _drive.Segment
    return (S("settle", 2.0, 0.0, 0.0), S("straight", 3.0, 0.2, 0.0), S("spin", math.pi / spin_rate, 0.0, spin_rate),
            S("back", 2.5, 0.2, 0.0), S("stop", 1.5, 0.0, 0.0))


def add_arguments(parser) -> None:
    parser.add_argument("--repeats", type=int, default=2, help="SimTwo runs (default 2)")
    parser.add_argument("--no-camera", action="store_true", help="do not open SimTwo's camera")
    parser.add_argument("--spin-rate", type=float, default=SPIN_RATE, metavar="RAD_S",
                        help=f"the turn on the spot's rate (default {SPIN_RATE})")


def one_run(camera: bool, spin_rate: float = SPIN_RATE) -> dict:
    return _drive.one_run("simtwo", camera, drive(spin_rate))


def run(args) -> dict:
    runs = []
    for k in range(args.repeats):
        print(f"[bench simtwo] run {k + 1} of {args.repeats}", flush=True)
        runs.append(one_run(not args.no_camera, args.spin_rate))
    return _drive.summarise(runs, {"camera": not args.no_camera, "spin_rate_rad_per_s": args.spin_rate})
