"""``raf experiment calibration``: does ``raf calibrate`` find a camera that is not the nominal one?

The stand-in simulator (in this process, its default SimTwo-like mode) renders the robot's camera with a
perturbed calibration -- by default the issue's case: fx and fy +3 %, cx +4 px, cy -3 px, pitch +1 degree
against the nominal values of the robot file -- while the robot drives a lap of the reference route
(pure pursuit on the ground truth) that sees floor and wall markers. Every ``--every``-th camera frame is
detected; odometry comes from the simulated encoders with the nominal wheel geometry while the simulated
robot's track is 1 % wider and its wheels 0.5 % smaller (``--wheel-error``, as in ``raf experiment
localization``); a frame's stamp is the end of the control cycle it was rendered in (what a receiver of
SimTwo's frames can know). The calibration
(:func:`robotatfactory.localization.calibration.calibrate`) starts from the NOMINAL camera and is compared
with the true one.

Targets (issue 9): fx and fy within 0.3 %, cx and cy within 0.5 px, pitch within 0.1 degree. Also reported:
roll, height and forward offset errors, the fit's residual before (nominal camera, poses fitted) and after,
and the reported 1-sigma uncertainties. With ``--out DIR``: ``calibration.yaml`` (the fitted camera, the file
``raf bridge --calibration`` and ``raf localize --calibration`` load), ``robot_true.json`` (the perturbed
robot, for ``raf sim --robot``), ``calibration_residuals.png`` and ``results.json``.

``--simulator simtwo``: the real SimTwo (:mod:`._calibration_simtwo`) renders the perturbed camera as far as
its GLScene camera can: fx and fy +3 % (one focal length) and pitch +1 degree by default; the principal point
stays at the image centre (cx, cy +0: a symmetric frustum), no roll, no distortion. The robot drives the
localization experiment's calibration drive (``raf simtwo run --robot`` with the perturbed robot file, raf
bridge, a rosbag) and ``raf calibrate --bag`` fits it from the nominal camera; the same keys against the
perturbed true camera.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

NAME = "calibration"
HELP = ("raf calibrate on frames rendered with a perturbed camera (stand-in: fx, fy +3 pct, cx +4 px, cy -3 px, "
        "pitch +1 deg; --simulator simtwo: fx, fy +3 pct, pitch +1 deg)")
TARGETS = {
    "fx_error_pct": "|.| <= 0.3 (issue 9)",
    "fy_error_pct": "|.| <= 0.3 (issue 9)",
    "cx_error_px": "|.| <= 0.5 (issue 9)",
    "cy_error_px": "|.| <= 0.5 (issue 9)",
    "pitch_error_deg": "|.| <= 0.1 (issue 9)",
}
LIMITS = {"fx_error_pct": 0.3, "fy_error_pct": 0.3, "cx_error_px": 0.5, "cy_error_px": 0.5, "pitch_error_deg": 0.1}


#: the stand-in's default principal-point perturbation (px); SimTwo's is 0 (its frustum is symmetric)
STANDIN_CX_PX, STANDIN_CY_PX = 4.0, -3.0
STANDIN_WHEEL_ERROR = "0.01,-0.005"


def add_arguments(parser) -> None:
    parser.add_argument("--simulator", choices=("standin", "simtwo"), default="standin",
                        help="standin: frames rendered in this process (default); simtwo: the real SimTwo with "
                             "its scene's camera perturbed (raf simtwo run --robot: fx = fy, principal point at the "
                             "centre), the localization experiment's calibration drive and raf calibrate --bag")
    parser.add_argument("--route", default="reference", choices=("reference", "second"),
                        help="route to drive (localization/route.py; default reference)")
    parser.add_argument("--laps", type=int, default=1, help="laps of the route (default 1)")
    parser.add_argument("--speed", type=float, default=0.2, help="cruise speed, m/s (default 0.2)")
    parser.add_argument("--every", type=int, default=2, help="use every N-th camera frame (default 2: 7.5 per s)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed")
    parser.add_argument("--fx-pct", type=float, default=3.0, help="true fx against the nominal, percent (default 3)")
    parser.add_argument("--fy-pct", type=float, default=3.0, help="true fy against the nominal, percent (default 3)")
    parser.add_argument("--cx-px", type=float, default=None,
                        help="true cx against the nominal, px (default 4; SimTwo: 0, the only value it renders)")
    parser.add_argument("--cy-px", type=float, default=None,
                        help="true cy against the nominal, px (default -3; SimTwo: 0, the only value it renders)")
    parser.add_argument("--pitch-deg", type=float, default=1.0, help="true pitch against the nominal, deg (default 1)")
    parser.add_argument("--roll-deg", type=float, default=0.0, help="true roll, deg (default 0)")
    parser.add_argument("--height-mm", type=float, default=0.0, help="true mount height against the nominal, mm")
    parser.add_argument("--forward-mm", type=float, default=0.0, help="true forward offset against the nominal, mm")
    parser.add_argument("--no-odometry", action="store_true", help="fit without the odometry prior")
    parser.add_argument("--wheel-error", default=None, metavar="TRACK,RADIUS",
                        help="relative errors of the simulated robot's track and wheel radius against the nominal "
                             "ones the odometry uses (default 0.01,-0.005, as raf experiment localization; not on "
                             "SimTwo, whose wheels are its scene's)")
    parser.add_argument("--fit-distortion", action="store_true", help="also fit k1, k2")
    parser.add_argument("--fit-corner-bias", action="store_true",
                        help="also fit a constant detector corner bias (px; docs/calibration.md: off by default)")
    parser.add_argument("--corner-refinement", default="apriltag", choices=("subpix", "contour", "apriltag", "none"),
                        help="ArUco corner refinement of the detector (default apriltag, raf calibrate's; "
                             "docs/calibration.md)")


def record(fld, true_robot, nominal_robot, route: str = "reference", laps: int = 1, speed: float = 0.2,
           every: int = 2, seed: int = 0, odometry: bool = True, timeout_s: float = 600.0,
           corner_refinement: str = "apriltag"):
    """Drive the route in the stand-in simulator (camera = ``true_robot``'s), detect markers in every
    ``every``-th frame. Returns (frames, info): :class:`FrameData` list (odometry from the encoders with
    ``nominal_robot``'s wheels, stamps at the end of the frame's control cycle) and counts."""
    from ..localization.calibration import FrameData
    from ..localization.detect import DetectorConfig, MarkerDetector
    from ..localization.odometry import DiffDriveOdometry
    from ..localization.route import PurePursuit, make_route
    from ..sim import SimConfig, Simulator
    from ..simtwo import Command

    r = make_route(route, laps)
    pp = PurePursuit.for_route(r, speed=speed)
    det = MarkerDetector(DetectorConfig(dictionary=fld.dictionary, corner_refinement=corner_refinement))
    cfg = SimConfig(seed=seed, start_pose=r.start, competition=False, lidar=False)
    sim = Simulator(fld, true_robot, cfg)
    odo = DiffDriveOdometry(nominal_robot)
    odo_t, odo_p = [], []
    pending = []  # (frame index, stamp, detections)
    frames_seen = 0
    t_wall = time.perf_counter()
    try:
        n_cycles = 0
        while not pp.done and time.perf_counter() - t_wall < timeout_s and n_cycles < 20000:
            v, w = pp.command(sim.pose)
            f = sim.step_cycle(Command(v, w, False))
            n_cycles += 1
            st = odo.update(f.enc_total[0], f.enc_total[1], f.time)
            odo_t.append(f.time)
            odo_p.append((st.x, st.y, st.theta))
            for cf in sim.take_frames():
                frames_seen += 1
                if cf.index % max(1, every):
                    continue
                dets = det.detect(cf.bgr())
                if dets:
                    pending.append((cf.index, f.time, dets))  # stamp: the end of the cycle it fell in
    finally:
        sim.close()
    odo_t = np.array(odo_t)
    odo_p = np.array(odo_p)
    odo_p[:, 2] = np.unwrap(odo_p[:, 2])
    out = []
    for _, stamp, dets in pending:
        o = None
        if odometry:
            o = tuple(float(np.interp(stamp, odo_t, odo_p[:, k])) for k in range(3))
        out.append(FrameData(stamp, dets, o))
    info = {"frames_rendered": frames_seen, "frames_with_markers": len(out),
            "drive_s": float(odo_t[-1]) if len(odo_t) else 0.0, "route_done": bool(pp.done),
            "record_wall_s": time.perf_counter() - t_wall}
    return out, info


def figure(result, result_nominal, errors: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cam = result.camera
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8))
    for a, res, title in ((ax[0], result_nominal, "nominal camera (poses fitted)"),
                          (ax[1], result, "calibrated camera")):
        p, r = res.points_px, res.residuals
        p95 = float(np.percentile(np.linalg.norm(r, axis=1), 95)) if len(r) else 1.0
        scale = float(f"{25.0 / max(p95, 1e-3):.2g}")  # the 95th percentile arrow is ~25 px long
        a.quiver(p[:, 0], p[:, 1], r[:, 0] * scale, r[:, 1] * scale, angles="xy", scale_units="xy", scale=1,
                 width=0.002, color="tab:red" if res is result_nominal else "tab:blue")
        a.set_xlim(0, cam.width)
        a.set_ylim(cam.height, 0)
        a.set_aspect("equal")
        a.set_title(f"{title}: residuals x{scale:g}\nRMS {res.residual_px_rms:.2f} px, {res.detections} markers, "
                    f"{res.frames} frames", fontsize=9)
        a.set_xlabel("u (px)")
        a.set_ylabel("v (px)")
    d0 = np.linalg.norm(result_nominal.residuals, axis=1)
    d1 = np.linalg.norm(result.residuals, axis=1)
    bins = np.linspace(0, max(1.0, float(np.percentile(d0, 99))), 60)
    ax[2].hist(d0, bins=bins, alpha=0.6, color="tab:red", label="nominal camera")
    ax[2].hist(d1, bins=bins, alpha=0.6, color="tab:blue", label="calibrated")
    ax[2].set_xlabel("corner residual (px)")
    ax[2].set_ylabel("corners")
    ax[2].set_yscale("log")
    txt = "\n".join(f"{k} {v:+.3f}" for k, v in errors.items())
    ax[2].text(0.98, 0.97, txt, transform=ax[2].transAxes, ha="right", va="top", fontsize=8, family="monospace")
    ax[2].legend(loc="center right", fontsize=8)
    fig.suptitle("raf experiment calibration (stand-in, default SimTwo-like mode)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args, out_dir: Path | None) -> dict:
    if getattr(args, "simulator", "standin") == "simtwo":
        from . import _calibration_simtwo

        return _calibration_simtwo.run(args, out_dir)
    from ..field import load_field
    from ..localization.calibration import (CalibrationConfig, calibrate, compare, perturbed_robot,
                                            write_calibration, write_robot_json)
    from ..robot import load_robot

    from dataclasses import replace

    from ..errors import ConfigError

    fld = load_field(args.field)
    nominal = load_robot("simtwo")
    args.cx_px = STANDIN_CX_PX if args.cx_px is None else args.cx_px
    args.cy_px = STANDIN_CY_PX if args.cy_px is None else args.cy_px
    args.wheel_error = args.wheel_error or STANDIN_WHEEL_ERROR
    try:
        track_err, radius_err = (float(v) for v in args.wheel_error.split(","))
    except ValueError:
        raise ConfigError(f"--wheel-error {args.wheel_error!r}: expected TRACK,RADIUS, e.g. 0.01,-0.005") from None
    true_robot = perturbed_robot(nominal, fx_pct=args.fx_pct, fy_pct=args.fy_pct, cx_px=args.cx_px,
                                 cy_px=args.cy_px, pitch_deg=args.pitch_deg, roll_deg=args.roll_deg,
                                 height_m=args.height_mm / 1000, forward_m=args.forward_mm / 1000)
    true_robot = replace(true_robot, track=nominal.track * (1 + track_err),
                         wheel_radius=nominal.wheel_radius * (1 + radius_err))
    frames, info = record(fld, true_robot, nominal, args.route, args.laps, args.speed, args.every, args.seed,
                          odometry=not args.no_odometry, corner_refinement=args.corner_refinement)
    t0 = time.perf_counter()
    cfg = CalibrationConfig(fit_distortion=args.fit_distortion, fit_corner_bias=args.fit_corner_bias)
    result = calibrate(frames, fld, nominal, cfg)
    fit_s = time.perf_counter() - t0
    nominal_fit = calibrate(frames, fld, nominal, CalibrationConfig(free=(), fit_forward=False))
    errors = compare(result.camera, true_robot.camera)
    out: dict = {k: round(v, 4) for k, v in errors.items()}
    for k, lim in LIMITS.items():
        out[k.replace("_error", "_abs_error")] = round(abs(errors[k]), 4)
        out[f"{k.rsplit('_', 1)[0]}_target_met"] = bool(abs(errors[k]) <= lim)
    c, t = result.camera, true_robot.camera
    out.update({
        "fx_fitted_px": round(c.fx, 3), "fx_true_px": round(t.fx, 3), "fy_fitted_px": round(c.fy, 3),
        "fy_true_px": round(t.fy, 3), "cx_fitted_px": round(c.cx, 3), "cx_true_px": round(t.cx, 3),
        "cy_fitted_px": round(c.cy, 3), "cy_true_px": round(t.cy, 3),
        "pitch_fitted_deg": round(c.pitch_down_deg, 4), "pitch_true_deg": round(t.pitch_down_deg, 4),
        "residual_px_rms": round(result.residual_px_rms, 4),
        "residual_px_rms_nominal_camera": round(nominal_fit.residual_px_rms, 4),
        "frames": result.frames, "detections": result.detections, "wall_detections": result.wall_detections,
        "rejected_detections": result.rejected, "odometry_links": result.odometry_links,
        "degenerate_params": ",".join(result.degenerate) or "none",
        "fit_s": round(fit_s, 2), "route": args.route, "laps": args.laps, "mode": "default (SimTwo-like)",
        "simulator": "standin",
        "wheel_error": args.wheel_error,
        **{k: (round(v, 3) if isinstance(v, float) else v) for k, v in info.items()},
    })
    for k, v in result.sigma.items():
        unit = {"x": "m", "z": "m"}.get(k, "")
        out[f"sigma_{k}{'_' + unit if unit else ''}"] = float(f"{v:.3g}")
    if out_dir is not None:
        out_dir = Path(out_dir)
        write_calibration(out_dir / "calibration.yaml", result)
        write_robot_json(true_robot, out_dir / "robot_true.json")
        figure(result, nominal_fit, {k: v for k, v in errors.items()}, out_dir / "calibration_residuals.png")
    return out
