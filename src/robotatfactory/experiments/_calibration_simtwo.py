"""``raf experiment calibration --simulator simtwo``: raf calibrate on the real SimTwo with its camera perturbed.

SimTwo renders its robot's camera with GLScene: one focal length (fx = fy), a symmetric frustum (the
principal point at the image centre), no distortion (docs/calibration.md). So the perturbation is what SimTwo
can render: by default fx and fy +3 % and pitch +1 degree against the nominal camera (the robot file's, which
the unedited scene renders); cx and cy stay centred (``--cx-px``/``--cy-px`` other than 0, a roll, or fx
and fy perturbed differently are refused). Mount height and forward offset (``--height-mm``,
``--forward-mm``) are installed too.

The perturbed robot file goes to ``raf simtwo run --robot FILE``, which writes its camera into the scene
copy's AGV.xml (:func:`robotatfactory.simtwo_linux.scene.install_camera`). The drive is the localization
experiment's calibration drive on SimTwo (:func:`._localization_record.calibration_drive`: the route
``calibration`` at ``--calibration-speed``, pure pursuit on SimTwo's ground truth, raf bridge on a private
ROS graph, a camera frame per 0.2 s and odom recorded to a bag), then ``raf calibrate --bag --hold cx,cy``
from the NOMINAL camera (the principal point held at the image centre, where GLScene renders it:
:data:`~robotatfactory.simtwo_linux.scene.SIMTWO_CALIBRATION`); the result has the stand-in's keys (errors
against the perturbed true camera, the targets) with ``simulator`` = simtwo. The stand-in's ``--route``,
``--laps``, ``--speed``, ``--every``, ``--wheel-error`` and fit options do not apply (refused when given).

SimTwo's scene shows the calibration drive few or no wall markers; floor markers alone leave focal length,
pitch and the principal point's cy on a line (docs/calibration.md, "Wall markers"). The held principal point
and square pixels (``raf calibrate --aspect-sigma``, the same
:data:`~robotatfactory.simtwo_linux.scene.SIMTWO_CALIBRATION`: GLScene has one focal length, so fy = fx is held,
not merely preferred) take that line away; ``wall_detections`` says how many wall markers the fit had.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from .calibration import LIMITS

#: the calibration drive's settings (the localization experiment's defaults)
CALIBRATION_SPEED = 0.15
DRIVE_TIMEOUT_S = 900.0


def check_args(args) -> None:
    """ConfigError for what SimTwo cannot render or the SimTwo run does not use."""
    from ..errors import ConfigError

    bad = []
    if (args.cx_px or 0.0) != 0.0 or (args.cy_px or 0.0) != 0.0:
        bad.append("--cx-px/--cy-px: SimTwo's principal point is the image centre (GLScene's frustum is symmetric)")
    if args.fx_pct != args.fy_pct:
        bad.append("--fx-pct and --fy-pct differ: GLScene has one focal length")
    if args.roll_deg:
        bad.append("--roll-deg: the roll is not installed into SimTwo's scene")
    if args.fit_distortion or args.fit_corner_bias:
        bad.append("--fit-distortion/--fit-corner-bias: raf calibrate's defaults run on SimTwo")
    if args.wheel_error:
        bad.append("--wheel-error: SimTwo's wheels are its scene's")
    if args.no_odometry:
        bad.append("--no-odometry: raf calibrate --bag uses the recorded odom")
    if (args.route, args.laps, args.speed, args.every) != ("reference", 1, 0.2, 2):
        bad.append("--route/--laps/--speed/--every: SimTwo drives the localization experiment's calibration drive")
    if args.corner_refinement != "apriltag":
        bad.append("--corner-refinement: raf calibrate's default (apriltag) runs on SimTwo")
    if bad:
        raise ConfigError("--simulator simtwo: " + "; ".join(bad))


def true_robot(args):
    """The nominal robot with SimTwo's share of the perturbation (fx = fy, pitch, mount)."""
    from ..errors import ConfigError
    from ..localization.calibration import perturbed_robot
    from ..robot import load_robot
    from ..simtwo_linux.scene import camera_refusals

    robot = perturbed_robot(load_robot("simtwo"), fx_pct=args.fx_pct, fy_pct=args.fy_pct, cx_px=0.0, cy_px=0.0,
                            pitch_deg=args.pitch_deg, roll_deg=0.0, height_m=args.height_mm / 1000,
                            forward_m=args.forward_mm / 1000)
    why = camera_refusals(robot.camera)
    if why:
        raise ConfigError("--simulator simtwo: " + "; ".join(why))
    return robot


def result_keys(calib: Path, truth) -> dict:
    """The stand-in experiment's keys for the calibration file ``calib`` against the true camera ``truth``."""
    from ..localization.calibration import compare, load_calibration

    cal = load_calibration(calib)
    c = cal.apply(truth)
    errors = compare(c, truth)
    out: dict = {k: round(v, 4) for k, v in errors.items()}
    for k, lim in LIMITS.items():
        out[k.replace("_error", "_abs_error")] = round(abs(errors[k]), 4)
        out[f"{k.rsplit('_', 1)[0]}_target_met"] = bool(abs(errors[k]) <= lim)
    for k in ("fx", "fy", "cx", "cy"):
        out[f"{k}_fitted_px"] = round(getattr(c, k), 3)
        out[f"{k}_true_px"] = round(getattr(truth, k), 3)
    out["pitch_fitted_deg"] = round(c.pitch_down_deg, 4)
    out["pitch_true_deg"] = round(truth.pitch_down_deg, 4)
    fit = cal.fit or {}
    out.update({
        "residual_px_rms": fit.get("residual_px_rms"), "frames": fit.get("frames"),
        "detections": fit.get("detections"), "wall_detections": fit.get("wall_detections"),
        "rejected_detections": fit.get("rejected"), "odometry_links": fit.get("odometry_links"),
        "degenerate_params": ",".join(fit.get("degenerate") or []) or "none",
    })
    for k, v in (fit.get("sigma") or {}).items():
        unit = {"x": "m", "z": "m"}.get(k, "")
        out[f"sigma_{k}{'_' + unit if unit else ''}"] = float(f"{v:.3g}")
    corr = fit.get("correlation") or {}
    if corr:
        k, v = max(corr.items(), key=lambda kv: abs(kv[1]))
        out["largest_correlation"] = f"{k} {v:+.3f}"
    return out


def run(args, out_dir: Path | None) -> dict:
    from ..localization.calibration import write_robot_json
    from ..robot import load_robot
    from ..simtwo_linux.scene import SIMTWO_CALIBRATION, field_for_simtwo, focal_length_mm
    from ._localization_record import calibration_drive, experiment_graph
    from .localization import REAL, Plan

    check_args(args)
    truth = true_robot(args)
    nominal = load_robot("simtwo")
    field = field_for_simtwo(args.field)
    work = Path(tempfile.mkdtemp(prefix="raf-exp-cal-simtwo-"))
    log_dir = (Path(out_dir) / "logs") if out_dir else work / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    robot_file = write_robot_json(truth, (Path(out_dir) if out_dir else work) / "robot_true.json")
    # what Session and calibration_drive read of the localization experiment's options
    largs = argparse.Namespace(field=field, timeout=DRIVE_TIMEOUT_S, set=[], no_beacons=True, save_bag=None,
                               calibration_speed=CALIBRATION_SPEED, seed=args.seed)
    plan = Plan(REAL, (), "auto", False, 0.0, 0.0, CALIBRATION_SPEED)
    notes: list[str] = []
    out: dict = {}
    t0 = time.monotonic()
    # the work folder (the ~100 MB bag) goes when the drive finished; logs live in out_dir/logs with --out
    with experiment_graph("raf_experiment_calibration", work, log_dir) as graph:
        calib, keys = calibration_drive(largs, plan, graph, log_dir, work, robot_file, nominal,
                                        Path(out_dir) if out_dir else None, notes,
                                        constraints=SIMTWO_CALIBRATION)
        out.update(result_keys(calib, truth.camera))
        out.update({
            "simulator": "simtwo", "field": field, "middleware": graph.middleware,
            "route": "calibration (raf experiment localization's calibration drive)", "laps": 1,
            "speed_m_per_s": CALIBRATION_SPEED,
            "perturbation": (f"fx, fy {args.fx_pct:+g} %, pitch {args.pitch_deg:+g} deg, height "
                             f"{args.height_mm:+g} mm, forward {args.forward_mm:+g} mm; cx, cy centred (SimTwo's "
                             "GLScene camera has a symmetric frustum)"),
            "focal_length_mm": round(focal_length_mm(truth.camera.fx), 4),
            "bag_images": keys.get("calibration_bag_images"), "bag_odom": keys.get("calibration_bag_odom"),
            "calibrate_wall_s": round(keys.get("calibration_wall_s", 0.0), 1),
            "calibration_held": keys.get("calibration_held"),
            "calibration_aspect_sigma": keys.get("calibration_aspect_sigma"),
            "wall_s": round(time.monotonic() - t0, 1),
        })
    if not out.get("wall_detections"):
        notes.append("no wall marker in the fit: floor markers alone cannot separate focal length, mount height "
                     "and pitch (docs/calibration.md), so fx and pitch trade against each other and the height")
    out["notes"] = "; ".join(notes)
    for n in notes:
        print(f"note: {n}")
    return out
