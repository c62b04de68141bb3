"""``raf experiment localization``'s analysis: the recorded pose streams and the simulator's ground truth
turned into numbers -- per-method error series, RMSE / 95th percentile / maximum of position and heading,
the EKF's consistency (NEES) and the filter's verdicts on the camera fixes, the flat result keys of one route
(unprefixed: :func:`analyse`), the table printed (:func:`table`) and the calibration's errors against the true
camera (:func:`calibration_keys`).

No ROS and no matplotlib here: the input is the recorder's arrays (``{stream: rows of (t, x, y, theta, ...)}``,
:meth:`._localization_record.Recorder.arrays`, or a run's ``*_data.npz``).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

BAD_FIX_M = 0.05  # an accepted camera fix further than this from the truth is a failure
METHODS = ("closest", "closest_checked", "all_pnp", "planar")
LABELS = {"odometry": "odometry alone", "closest": "closest marker (paper)", "closest_checked":
          "closest marker + mount check", "all_pnp": "all-marker PnP", "planar": "planar fit (mount fixed)",
          "ekf": "EKF (odometry + planar fixes + beacons)"}


def analyse(d: dict, done_t: float | None) -> tuple[dict, dict]:
    """Per-method error series and the flat result dict."""
    from ..localization.metrics import errors, odometry_in_map, path_length, stats

    gt = d["gt"]
    t_gt, P_gt = gt[:, 0], gt[:, 1:4]
    t_end = done_t if done_t is not None else t_gt[-1]
    keep = t_gt <= t_end + 1e-9
    t_gt, P_gt = t_gt[keep], P_gt[keep]
    series = {}
    odo = d["odom"]
    odo = odo[odo[:, 0] <= t_end + 1e-9]
    if len(odo):
        from ..localization.metrics import interpolate

        start = interpolate(odo[:1, 0], t_gt, P_gt)[0]
        series["odometry"] = (odo[:, 0], odometry_in_map(odo[:, 1:4], tuple(start)))
    for m in ("ekf", *METHODS):
        a = d[m]
        if len(a):
            a = a[a[:, 0] <= t_end + 1e-9]
            series[m] = (a[:, 0], a[:, 1:4])
    out = {"route_duration_sim_s": float(t_gt[-1] - t_gt[0]), "route_length_m": path_length(P_gt),
           "route_completed": done_t is not None}
    errs = {}
    for m, (t, P) in series.items():
        te, ep, eh = errors(t, P, t_gt, P_gt)
        errs[m] = (te, ep, eh)
        sp, sh = stats(ep), stats(eh)
        out[f"{m}_samples"] = sp["n"]
        out[f"{m}_position_rmse_m"] = sp["rmse"]
        out[f"{m}_position_p95_m"] = sp["p95"]
        out[f"{m}_position_max_m"] = sp["max"]
        out[f"{m}_heading_rmse_deg"] = math.degrees(sh["rmse"]) if sh["n"] else math.nan
        out[f"{m}_heading_p95_deg"] = math.degrees(sh["p95"]) if sh["n"] else math.nan
        out[f"{m}_heading_max_deg"] = math.degrees(sh["max"]) if sh["n"] else math.nan
    # at the end of the route: mean error over the last second
    for m in ("odometry", "ekf"):
        if m in errs and len(errs[m][0]):
            te, ep, eh = errs[m]
            last = te >= te[-1] - 1.0
            out[f"{m}_end_position_error_m"] = float(np.mean(ep[last]))
            out[f"{m}_end_heading_error_deg"] = math.degrees(float(np.mean(eh[last])))
    if "ekf" in errs:
        # consistency of the EKF's covariance: mean normalised error squared over the drive (3 expected)
        a = d["ekf"]
        a = a[a[:, 0] <= t_end + 1e-9]
        from ..localization.geometry import wrap_angle
        from ..localization.metrics import interpolate

        ref = interpolate(a[:, 0], t_gt, P_gt)
        ok = np.all(np.isfinite(ref), axis=1)
        dd = a[ok, 1:4] - ref[ok]
        dd[:, 2] = wrap_angle(dd[:, 2])
        var = a[ok, 4:7]
        out["ekf_nees_diag_mean"] = float(np.mean(np.sum(dd ** 2 / np.maximum(var, 1e-18), axis=1)))
    # the filter's final verdict on each camera fix: accepted fixes far from the truth are failures
    for key in ("accepted", "rejected"):
        a = d.get(key, np.zeros((0, 4)))
        a = a[a[:, 0] <= t_end + 1e-9] if len(a) else a
        n, n_bad, emax = 0, 0, math.nan
        if len(a):
            te, ep, eh = errors(a[:, 0], a[:, 1:4], t_gt, P_gt)
            n, n_bad = len(ep), int(np.sum(ep > BAD_FIX_M))
            emax = float(np.max(ep)) if len(ep) else math.nan
            if key == "accepted":
                errs["accepted"] = (te, ep, eh)
        out[f"ekf_{key}_fixes"] = n
        out[f"ekf_{key}_fixes_over_5cm"] = n_bad
        out[f"ekf_{key}_fix_error_max_m"] = emax
    ekf_rmse = out.get("ekf_position_rmse_m", math.nan)
    out["closest_over_ekf_position_rmse"] = out.get("closest_position_rmse_m", math.nan) / ekf_rmse
    out["odometry_over_ekf_end_position_error"] = (out.get("odometry_end_position_error_m", math.nan)
                                                   / max(out.get("ekf_end_position_error_m", math.nan), 1e-6))
    out["ekf_position_rmse_target_met"] = bool(ekf_rmse <= 0.010)
    out["ekf_heading_rmse_target_met"] = bool(out.get("ekf_heading_rmse_deg", math.inf) <= 1.0)
    out["ekf_3x_closest_target_met"] = bool(out["closest_over_ekf_position_rmse"] >= 3)
    out["ekf_no_bad_fix_accepted_target_met"] = bool(out["ekf_accepted_fixes"] > 0
                                                     and out["ekf_accepted_fixes_over_5cm"] == 0)
    out["ekf_10x_odometry_end_met"] = bool(out["odometry_over_ekf_end_position_error"] >= 10)
    return errs, out


def table(out: dict, title: str = "") -> str:
    rows = [title] if title else []
    rows += ["| method | samples | position RMSE / p95 / max (cm) | heading RMSE / p95 / max (deg) |",
             "|---|---|---|---|"]
    for m in ("odometry", *METHODS, "ekf"):
        if f"{m}_samples" not in out:
            continue
        g = lambda k, m=m: out.get(f"{m}_{k}", math.nan)  # noqa: E731
        rows.append(f"| {LABELS[m]} | {out[f'{m}_samples']} | {100 * g('position_rmse_m'):.2f} / "
                    f"{100 * g('position_p95_m'):.2f} / {100 * g('position_max_m'):.2f} | "
                    f"{g('heading_rmse_deg'):.2f} / {g('heading_p95_deg'):.2f} / {g('heading_max_deg'):.2f} |")
    if "ekf_accepted_fixes" in out:
        rows.append(f"\ncamera fixes accepted by the filter: {out['ekf_accepted_fixes']} (over 5 cm off: "
                    f"{out['ekf_accepted_fixes_over_5cm']}, worst {100 * out['ekf_accepted_fix_error_max_m']:.2f} cm); "
                    f"rejected: {out['ekf_rejected_fixes']} ({out['ekf_rejected_fixes_over_5cm']} over 5 cm off)")
    return "\n".join(rows)


def calibration_keys(calib: Path | None, true_camera) -> dict:
    """The calibration's values and their errors against the stand-in's true camera."""
    if calib is None:
        return {}
    from ..localization.calibration import compare, load_calibration

    c = load_calibration(calib).apply(true_camera)
    out = {f"calibration_{k}": float(getattr(c, k)) for k in ("fx", "fy", "cx", "cy", "pitch_down_deg")}
    out.update({f"calibration_{k}": float(v) for k, v in compare(c, true_camera).items()})
    return out
