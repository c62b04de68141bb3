"""``raf experiment compare``: the stand-in and the real SimTwo side by side, figure by figure, over repeats.

Runs the same measurements on both simulators (``--simulators``, default both) and puts each figure's range
over the repeats in adjacent columns:

- ``drive``: ``raf bench drive``'s scripted drive (no ROS): frame rate, replies applied, camera rate and
  latency, LIDAR sweeps, self-hits and range error against the walls, odometry per segment (straights, arcs,
  turns on the spot at two rates) and over the whole drive;
- ``speed``: ``raf experiment speed`` through ROS (the paper's figure 5): RMS error, lag, steady speed;
- ``localization``: ``raf experiment localization`` (its calibration drive, then ``--route``, default the
  reference route, one lap): the calibration ``raf calibrate`` recovers, on both simulators with what SimTwo's
  renderer fixes held (``--calibrate-as simtwo``: the principal point and square pixels; the stand-in's MuJoCo
  camera renders them alike), and the position and heading RMSE of odometry, the paper's closest marker, the
  planar fit and the EKF;
- ``competition``: ``raf experiment competition``'s whole stack, round 1 (``--rounds``) over ``--seeds``:
  points, the last delivery, pick failures, pose error while docking.

Per figure: ``{figure}_{simulator}_min/_median/_max``, the difference of the medians (SimTwo - stand-in),
the larger of the two ranges (``_spread``) and ``_beyond_spread``: the difference is larger than that spread
(with one run per simulator there is no spread: every difference counts). Every key says which simulator
produced it. Like with like: both on SimTwo's field (``simtwo2022``), both free-running, the stand-in in its
default (SimTwo-like) mode and with SimTwo's wheels (the localization's added wheel error off). The ROS
experiments run as processes of their own (``raf experiment NAME --out DIR``: a ROS 1 node is initialised once
per process); a failed run is counted (``failed_runs``, ``failures``) and the comparison goes on. The real
SimTwo needs about one core and runs in real time: the whole comparison takes about an hour with the defaults;
``--parts``, ``--repeats`` and ``--calibration none`` make it shorter (the suite runs ``--repeats 1 --seeds 1
--calibration none``: tests/test_simtwo_compare.py).
"""
from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

NAME = "compare"
HELP = ("the stand-in and the real SimTwo side by side: the same drive, speed test, localization and rounds, "
        "repeated; each figure's range per simulator and whether they differ beyond the runs' spread")
SIMULATORS = ("standin", "simtwo")
PARTS = ("drive", "speed", "localization", "competition")
TARGETS: dict = {}

#: (part, key in the part's flat results, label, unit, scale): the figures compared, in the table's order
DRIVE_FIGURES = (
    ("frames_per_s_sim", "SensorFrames per s of simulation", "1/s", 1.0),
    ("sim_time_per_wall_time", "simulation time per wall time", "-", 1.0),
    ("replies_applied_share", "replies applied, share of cycles", "-", 1.0),
    ("camera_frames_per_s", "camera frames per wall s", "1/s", 1.0),
    ("camera_after_sensorframe_ms", "camera frame after its SensorFrame, median", "ms", 1.0),
    ("lidar_sweeps_per_s_sim", "LIDAR sweeps per s of simulation", "1/s", 1.0),
    ("lidar_self_hits_per_sweep", "LIDAR returns inside the robot per sweep", "-", 1.0),
    ("lidar_wall_abs_error_rest_mm_median", "LIDAR range error vs walls at rest, median abs", "mm", 1.0),
    ("lidar_wall_abs_error_moving_mm_median", "LIDAR range error vs walls moving, median abs", "mm", 1.0),
    ("straight_odom_over_truth", "straight from rest: encoders / truth", "-", 1.0),
    ("arc_right_odom_error_mm_per_m", "odometry error, arc right", "mm/m", 1.0),
    ("arc_left_odom_error_mm_per_m", "odometry error, arc left", "mm/m", 1.0),
    ("spin_slow_truth_over_odom_turn", "turn on the spot 0.5 rad/s: truth / encoders", "-", 1.0),
    ("spin_fast_truth_over_odom_turn", "turn on the spot 1.5 rad/s: truth / encoders", "-", 1.0),
    ("after_spin_truth_turn_deg", "straight after a spin: the truth's turn", "deg", 1.0),
    ("after_spin_odom_minus_truth_turn_deg", "straight after a spin: odometry - truth turn", "deg", 1.0),
    ("odom_error_mm_per_m", "odometry error, whole drive", "mm/m", 1.0),
    ("odom_heading_error_deg", "odometry heading error, whole drive", "deg", 1.0),
    ("clearance_min_m", "the drive's clearance from posts and walls (a check)", "m", 1.0),
)
SPEED_FIGURES = (
    ("speed_rmse_mps", "speed test RMS error", "mm/s", 1000.0),
    ("speed_lag_ms", "speed test lag", "ms", 1.0),
    ("speed_steady_mean_mps", "speed test steady speed (0.3 m/s asked)", "m/s", 1.0),
)
LOCALIZATION_FIGURES = (
    ("calibration_fx_error_pct", "raf calibrate: fx against the nominal", "%", 1.0),
    ("calibration_cy_error_px", "raf calibrate: cy against the nominal", "px", 1.0),
    ("calibration_pitch_error_deg", "raf calibrate: pitch against the nominal", "deg", 1.0),
    ("odometry_position_rmse_m", "odometry alone, position RMSE", "mm", 1000.0),
    ("closest_position_rmse_m", "closest marker (paper), position RMSE", "mm", 1000.0),
    ("planar_position_rmse_m", "planar fit, position RMSE", "mm", 1000.0),
    ("ekf_position_rmse_m", "EKF position RMSE", "mm", 1000.0),
    ("ekf_heading_rmse_deg", "EKF heading RMSE", "deg", 1.0),
    ("ekf_accepted_fixes_over_5cm", "accepted fixes > 5 cm off", "-", 1.0),
)
COMPETITION_FIGURES = (
    ("points", "round points", "-", 1.0),
    ("max_score", "maximum score reached (1 = yes)", "-", 1.0),
    ("last_score_s", "last scoring delivery", "s", 1.0),
    ("picks_attempted", "picks attempted", "-", 1.0),
    ("pick_failures", "failed picks", "-", 1.0),
    ("parts_knocked_out", "parts knocked out of a slot", "-", 1.0),
    ("pose_error_docking_max_m", "pose error while docking, max", "mm", 1000.0),
)
FIGURES = {"drive": DRIVE_FIGURES, "speed": SPEED_FIGURES, "localization": LOCALIZATION_FIGURES,
           "competition": COMPETITION_FIGURES}


def add_arguments(parser) -> None:
    parser.add_argument("--parts", default=",".join(PARTS),
                        help=f"comma-separated measurements (default {','.join(PARTS)})")
    parser.add_argument("--simulators", default=",".join(SIMULATORS),
                        help="comma-separated: standin, simtwo (default both)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of drive, speed and localization per simulator "
                                                             "(default 3)")
    parser.add_argument("--rounds", default="1", help="competition rounds (default 1)")
    parser.add_argument("--seeds", type=int, default=3, help="competition seeds 0..N-1 per round (default 3)")
    parser.add_argument("--route", default="reference", choices=("reference", "second"),
                        help="the localization's route (default reference), one lap")
    parser.add_argument("--calibration", default="auto", choices=("auto", "none"),
                        help="the localization's camera: auto (raf calibrate on a calibration drive first, default) "
                             "or none (the robot file's nominal camera: shorter)")


def _choice(text: str, allowed, option: str) -> list[str]:
    from ..errors import ConfigError

    items = [x.strip() for x in str(text).split(",") if x.strip()]
    bad = [x for x in items if x not in allowed]
    if not items or bad:
        raise ConfigError(f"{option} {text!r}: choose from {', '.join(allowed)}")
    return items


def experiment_args(module, field: str, *argv: str) -> argparse.Namespace:
    """An experiment's options as its own parser fills them (its defaults, then ``argv``)."""
    p = argparse.ArgumentParser(prog=f"raf experiment {module.NAME}")
    p.add_argument("--field", default=field)
    module.add_arguments(p)
    return p.parse_args(list(argv))


# ------------------------------------------------------------------------------------- one measurement
def measure_drive(simulator: str, field: str, out_dir: Path | None, k: int) -> list[dict]:
    from ..bench import drive

    return [drive.one_run(simulator)]


def run_experiment(name: str, field: str, out: Path, *argv: str, timeout: float = 3600.0) -> dict:
    """``raf experiment NAME ARGV --out OUT`` in a process of its own (a ROS 1 node can be initialised once per
    process: each experiment gets a fresh one); its results.json. A failed run raises RuntimeError with the
    end of its output."""
    import json
    import subprocess

    from ..ros.processes import raf_cmd

    out.mkdir(parents=True, exist_ok=True)
    log = out / "experiment.log"
    with open(log, "w") as f:
        proc = subprocess.run(raf_cmd("--field", field, "experiment", name, *argv, "--out", str(out)), stdout=f,
                              stderr=subprocess.STDOUT, timeout=timeout)
    try:
        return json.loads((out / "results.json").read_text())
    except (OSError, ValueError):
        tail = log.read_text(errors="replace").strip().splitlines()[-3:]
        raise RuntimeError(f"raf experiment {name} failed (exit {proc.returncode}): {' | '.join(tail)}") from None


def measure_speed(simulator: str, field: str, out_dir: Path, k: int) -> list[dict]:
    # free-running on both (the default: SimTwo cannot wait for a reply, the stand-in's --lockstep is an
    # idealisation), the bare loop (--lead-ms 0), so that the lags compare the two simulators' loops
    return [run_experiment("speed", field, out_dir / f"speed_{simulator}_{k}", "--simulator", simulator,
                           "--lead-ms", "0")]


def measure_localization(simulator: str, field: str, out_dir: Path, k: int, route: str,
                         calibration: str = "auto") -> list[dict]:
    from . import localization as loc

    # the stand-in's wheels as SimTwo's scene builds them (no extra calibration error: SimTwo has none either)
    res = run_experiment("localization", field, out_dir / f"localization_{simulator}_{k}", "--simulator", simulator,
                         "--route", route, "--laps", "1", "--no-rviz", "--no-tf-tree", "--calibration", calibration,
                         "--calibrate-as", "simtwo",  # both calibrated alike: held where GLScene and MuJoCo render alike
                         *(["--wheel-error", "0,0"] if simulator == "standin" else []))
    prefix = f"{loc.REAL if simulator == 'simtwo' else 'simtwo'}_"
    out = {}
    for key, v in res.items():
        if key.startswith(prefix + route + "_"):
            out[key[len(prefix + route) + 1:]] = v
        elif key.startswith(prefix + "calibration_"):
            out[key[len(prefix):]] = v
    return [out]


def measure_competition(simulator: str, field: str, out_dir: Path | None, rounds: list[int], seeds: int) -> list[dict]:
    from .competition import _full_job

    return [_full_job(r, s, out_dir, False, field, simulator) for r in rounds for s in range(seeds)]


# ------------------------------------------------------------------------------------------ the table
def summarise(values: dict, parts: list[str], sims: list[str]) -> dict:
    """``values[part][simulator]``: the list of result dicts; the flat comparison (see the module docstring)."""
    out: dict = {}
    for part in parts:
        for key, _label, _unit, scale in FIGURES[part]:
            meds = {}
            spread = 0.0
            for sim in sims:
                vals = [float(r[key]) * scale for r in values.get(part, {}).get(sim, [])
                        if isinstance(r.get(key), (int, float, bool)) and math.isfinite(float(r[key]))]
                if not vals:
                    continue
                out[f"{key}_{sim}_min"] = min(vals)
                out[f"{key}_{sim}_median"] = meds[sim] = statistics.median(vals)
                out[f"{key}_{sim}_max"] = max(vals)
                out[f"{key}_{sim}_runs"] = len(vals)
                spread = max(spread, max(vals) - min(vals))
            if len(meds) == 2:
                diff = meds["simtwo"] - meds["standin"]
                out[f"{key}_difference"] = diff
                out[f"{key}_spread"] = spread
                out[f"{key}_beyond_spread"] = abs(diff) > spread
    return out


def table(out: dict, parts: list[str], sims: list[str]) -> str:
    def rng(key, sim):
        if f"{key}_{sim}_median" not in out:
            return "-"
        lo, med, hi = (out[f"{key}_{sim}_{s}"] for s in ("min", "median", "max"))
        return f"{med:.4g}" if lo == hi else f"{lo:.4g} .. {hi:.4g}"

    head = f"| figure | unit | {' | '.join('stand-in' if s == 'standin' else 'SimTwo' for s in sims)} | differs |"
    lines = [head, "|" + "---|" * (3 + len(sims))]
    for part in parts:
        for key, label, unit, _scale in FIGURES[part]:
            beyond = out.get(f"{key}_beyond_spread")
            mark = "-" if beyond is None else ("**yes**" if beyond else "no")
            lines.append(f"| {label} | {unit} | {' | '.join(rng(key, s) for s in sims)} | {mark} |")
    return "\n".join(lines)


def run(args, out_dir: Path | None) -> dict:
    from ..errors import ConfigError

    parts = _choice(args.parts, PARTS, "--parts")
    sims = _choice(args.simulators, SIMULATORS, "--simulators")
    if args.repeats < 1 or args.seeds < 1:
        raise ConfigError("--repeats and --seeds must be at least 1")
    rounds = [int(x) for x in _choice(args.rounds, ("1", "2", "3"), "--rounds")]
    field = getattr(args, "field", None)
    from ..field import DEFAULT_FIELD

    from ..simtwo_linux.scene import field_for_simtwo

    field = field_for_simtwo(field or DEFAULT_FIELD)  # both on SimTwo's scene's field (simtwo2022)
    import tempfile

    work = out_dir if out_dir is not None else Path(tempfile.mkdtemp(prefix="raf-compare-"))
    values: dict = {}
    timing: dict = {}
    failures: list[str] = []
    for part in parts:
        for sim in sims:
            t0 = time.monotonic()
            got: list[dict] = []
            if part == "competition":
                print(f"[compare] {part} on {sim}: rounds {rounds}, {args.seeds} seed(s)", flush=True)
                got = measure_competition(sim, field, work, rounds, args.seeds)
            else:
                for k in range(args.repeats):
                    print(f"[compare] {part} on {sim}: run {k + 1} of {args.repeats}", flush=True)
                    try:
                        if part == "localization":
                            got += measure_localization(sim, field, work, k, args.route, args.calibration)
                        else:
                            got += {"drive": measure_drive, "speed": measure_speed}[part](sim, field, work, k)
                    except Exception as e:  # noqa: BLE001 - a failed run is reported, the comparison goes on
                        failures.append(f"{part} on {sim}, run {k + 1}: {type(e).__name__}: {e}")
                        print(f"[compare] {failures[-1]}", flush=True)
            values.setdefault(part, {})[sim] = got
            timing[f"{part}_{sim}_wall_s"] = round(time.monotonic() - t0, 1)
    out = summarise(values, parts, sims)
    out.update(timing)
    out["failed_runs"] = len(failures)
    out["failures"] = "; ".join(failures)
    out["stand_in_mode"] = ("raf sim defaults (SimTwo-like), free-running (no lockstep) in every part, field "
                            f"{field}, no added wheel error")
    text = table(out, parts, sims)
    print(text, flush=True)
    if out_dir is not None:
        (out_dir / "compare.md").write_text(text + "\n")
        import json

        (out_dir / "runs.json").write_text(json.dumps(values, indent=1, default=str))
    return out
