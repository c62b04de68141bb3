"""Camera calibration against the field: intrinsics and mount from many frames of a robot moving on it.

The markers' world corners are known (the field map), the robot's pose in each frame is not. One joint
least-squares problem over all frames (:func:`calibrate`) estimates

* the camera's intrinsics ``fx, fy, cx, cy`` (pixels; OpenCV's convention, pixel centres at integers) and,
  on request, radial/tangential distortion (OpenCV's k1, k2, p1, p2, k3);
* its mount on ``base_link``: height ``z``, forward offset ``x`` (only with odometry, see below), the pitch
  down and the roll about the optical axis (degrees; :class:`~robotatfactory.robot.CameraSpec`'s
  conventions); the lateral offset ``y`` and the yaw are held at their initial values;
* every frame's robot pose (x, y, heading) on the floor,

by minimising the reprojection error of every detected corner (pixels), with odometry (relative motion
between consecutive frames) as an optional prior on the poses and a weak prior on the camera towards its
initial values (it only decides directions the data leave free, and :class:`CalibrationResult.degenerate`
names them). ``scipy.optimize.least_squares`` (trust region reflective, LSMR on a sparse Jacobian, Huber
loss): each corner depends on the camera and on its own frame's pose only, so the Jacobian is the camera's
dense columns plus one 3-column block per frame (central differences: one projection of all corners per
camera parameter, one per pose coordinate for all frames at once), the odometry rows analytic. Huber's
threshold starts at three robust standard deviations of the first residuals (a camera several pixels off
makes every residual look like an outlier) and comes down to ``huber_sigmas`` over the rounds.

Robustness: each frame is seeded by the planar pose fit (:func:`~.estimators.planar_fit`, lenient settings)
with the initial camera; detections whose RMS residual is far above the fit's robust scale are rejected
(and readmitted when they fit again) over a few rounds.

Uncertainty: the covariance of the camera parameters is ``(J^T J)^-1`` at the solution, scaled by the
residuals' a-posteriori variance; the standard deviations are reported per parameter.

What the data must contain (degeneracies):

* Floor markers alone cannot separate focal length, height and pitch. All floor views share one plane whose
  orientation relative to the camera never changes (the robot only moves in that plane): the frames' floor
  homographies differ only by a planar motion, which leaves 5 identifiable combinations of the 7 camera
  parameters. Markers on a second plane at a known height (the field's wall markers, vertical, 0.1 m up,
  facing four directions) break it: the data must contain wall markers in a good share of the frames, seen
  at several places in the image. Without them, what closes the line is knowledge of the camera: a
  principal point held where it is known to be (``free`` without cx, cy: SimTwo's GLScene camera renders it
  at the image centre) together with square pixels (``aspect_sigma``, a prior on fy/fx, on by default; wall
  markers, when seen, outweigh it). Measured on synthetic floor-only frames of SimTwo's camera 3 % and
  1 degree off: 0.0 % in fx and fy, 0.003 degrees in pitch with both; 2 % in fy and a degenerate pitch with
  neither; the prior alone still leaves cy and the pitch on a line.
* The forward offset of the camera is absorbed by the per-frame poses (shifting every pose along its heading
  reproduces the same views) unless the poses are tied together: with odometry and turns (the camera moves on
  a circle of radius ``x`` when the robot turns on the spot) it is observable; without odometry it is held.
* Frames should cover the image (corners near its edges pin cx, cy and distortion) and the robot should
  turn and drive at different distances to the walls.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Iterable, Sequence

import numpy as np

from ...errors import ConfigError
from ...field.model import Field
from ...robot import CameraSpec, RobotSpec
from ..geometry import between2, wrap_angle
from .model import (DEFAULT_FREE, DISTORTION, PARAMS, FrameData, camera_from_vector, camera_vector,
                    predict_corners)


@dataclass
class CalibrationConfig:
    """Settings of the fit (units in the names).

    ``free``: camera parameters to estimate (from :data:`PARAMS`); ``x`` is added automatically when
    odometry is given and ``fit_forward`` is True; ``fit_distortion`` adds k1, k2 (``distortion_terms``
    picks which of k1..k3, p1, p2)."""

    free: tuple[str, ...] = DEFAULT_FREE
    fit_forward: bool = True
    fit_distortion: bool = False
    # the detector's corners sit a fraction of a pixel inside the printed square's (measured on the stand-in's
    # frames: 0.2-0.4 px); unmodelled, that shrinks every marker and biases focal length and pitch. One
    # parameter, an outward shift of each corner along the marker's diagonal in pixels, absorbs it.
    fit_corner_bias: bool = False
    distortion_terms: tuple[str, ...] = ("k1", "k2")
    sigma_px: float = 0.5  # corner noise, 1 sigma per coordinate (scales the residuals)
    huber_sigmas: float = 3.0  # residuals beyond this many sigmas count linearly (Huber)
    outlier_px: float = 3.0  # a marker whose RMS residual exceeds max(this, outlier_scales * robust scale)
    outlier_scales: float = 6.0  # is rejected (readmitted when it fits again)
    rounds: int = 6  # fit / reject rounds at most
    # odometry prior between consecutive frames: sigma = base + per metre (or per radian) of motion
    odom_sigma_xy_m: float = 0.002
    odom_sigma_xy_per_m: float = 0.02
    odom_sigma_theta_deg: float = 0.3
    odom_sigma_theta_per_rad: float = 0.02
    odom_max_gap_s: float = 2.0  # consecutive frames further apart than this are not tied by odometry
    # uncertainty of a frame's stamp (s, 1 sigma): SimTwo's frames are known only to the control cycle they
    # fell in (40 ms, uniform: 12 ms); the motion in that time adds to the odometry link's sigma
    stamp_sigma_s: float = 0.012
    # weak prior on the camera towards its initial values (decides only what the data leave free)
    prior_sigma: dict = field(default_factory=lambda: {
        "fx": 0.2, "fy": 0.2, "cx": 0.1, "cy": 0.1,  # relative to fx (cx, cy: fraction of the width)
        "x": 0.05, "y": 0.05, "z": 0.05, "pitch_down_deg": 10.0, "roll_deg": 10.0,
        "k1": 0.5, "k2": 0.5, "p1": 0.05, "p2": 0.05, "k3": 0.5, "corner_bias_px": 1.0})
    # prior on the pixels' aspect ratio fy / fx towards the initial camera's (relative, 1 sigma; 0: off). Square
    # pixels are what SimTwo's GLScene camera renders and nearly every real camera has; floor markers alone leave
    # fx, fy and the pitch on a line (module doc) that this prior crosses
    aspect_sigma: float = 0.005
    degenerate_ratio: float = 0.3  # a parameter whose sigma exceeds this share of its prior's is "degenerate"
    min_frames: int = 10
    min_detections: int = 40
    max_nfev: int = 200

    def check(self) -> None:
        bad = sorted(set(self.free) - set(PARAMS))
        if bad:
            raise ConfigError(f"calibration: unknown camera parameter(s) {bad}; known: {list(PARAMS)}")
        bad = sorted(set(self.distortion_terms) - set(DISTORTION))
        if bad:
            raise ConfigError(f"calibration: unknown distortion term(s) {bad}; known: {list(DISTORTION)}")
        for k in ("sigma_px", "huber_sigmas", "outlier_px", "odom_sigma_xy_m", "odom_sigma_theta_deg"):
            if not float(getattr(self, k)) > 0:
                raise ConfigError(f"calibration: {k} must be > 0, got {getattr(self, k)!r}")
        if not float(self.aspect_sigma) >= 0:
            raise ConfigError(f"calibration: aspect_sigma must be >= 0 (0: no prior), got {self.aspect_sigma!r}")


# -------------------------------------------------------------------------------------------- the result


@dataclass
class CalibrationResult:
    """The fitted camera and how well the data determine it."""

    camera: CameraSpec
    initial: CameraSpec
    free: tuple[str, ...]
    sigma: dict[str, float]  # 1-sigma uncertainty of each free parameter (units of :data:`UNITS`)
    residual_px_rms: float  # RMS of the inlier corners' residuals (pixels, per coordinate)
    residual_px_median: float  # median corner residual distance (pixels)
    frames: int  # frames used
    detections: int  # marker detections used (inliers)
    rejected: int  # detections rejected as outliers
    frames_dropped: int  # frames without a usable pose seed or without inliers
    wall_detections: int
    floor_detections: int
    odometry_links: int  # consecutive-frame odometry constraints used
    degenerate: tuple[str, ...]  # free parameters the data hardly determine (see module doc)
    correlation: dict[str, float]  # the largest correlations between free parameters ("a/b": r)
    poses: np.ndarray  # Nx3 fitted robot poses of the frames used
    stamps: np.ndarray  # N frame stamps
    residuals: np.ndarray  # Mx2 inlier corner residuals (observed - predicted... predicted - observed, px)
    points_px: np.ndarray  # Mx2 the inlier corners' observed pixels
    cost: float = float("nan")
    nfev: int = 0
    notes: tuple[str, ...] = ()
    corner_bias_px: float = 0.0  # fitted detector corner bias (outward +), pixels

    def summary(self) -> dict:
        """Flat dictionary of the fit (for YAML ``fit:`` and the experiments)."""
        return {
            "residual_px_rms": round(self.residual_px_rms, 4),
            "residual_px_median": round(self.residual_px_median, 4),
            "corner_bias_px": round(self.corner_bias_px, 4),
            "frames": self.frames, "detections": self.detections, "rejected": self.rejected,
            "frames_dropped": self.frames_dropped, "wall_detections": self.wall_detections,
            "floor_detections": self.floor_detections, "odometry_links": self.odometry_links,
            "free": list(self.free),
            "sigma": {k: float(f"{v:.4g}") for k, v in self.sigma.items()},
            "degenerate": list(self.degenerate),
            "correlation": {k: round(v, 3) for k, v in self.correlation.items()},
            "notes": list(self.notes),
        }


# ---------------------------------------------------------------------------------------------- the fit


def _seed_poses(frames: list[FrameData], fld: Field, robot: RobotSpec) -> list[tuple[tuple, set[int]] | None]:
    """Per frame: (pose, ids of markers the planar fit kept) with the initial camera, or None."""
    from ..markerpose import PoseConfig
    from ..pipeline import FrameLocalizer

    lenient = PoseConfig(mount_max_height_m=0.08, mount_max_tilt_deg=15.0, marker_max_rms_px=12.0,
                         marker_rms_sigmas=40.0, lone_marker_max_distance_m=1.2, marker_outlier_chi2=3.0e4,
                         max_rms_px=12.0, max_position_sigma_m=0.2, max_heading_sigma_deg=20.0,
                         consensus_px=25.0, max_marker_distance_m=3.0)
    loc = FrameLocalizer(fld, robot, pose=lenient, methods=("planar",))
    out = []
    for f in frames:
        res = loc.process_detections(f.detections)
        e = res.estimates.get("planar")
        if e is None or not e.ok:
            out.append(None)
        else:
            out.append((e.base, set(e.marker_ids)))
    return out


def _stack_frames(frames, seeds, fld: Field):
    """Corner arrays of every detection of a seeded frame: world P (Mx3), observed uv (Mx2), frame index
    (M), detection index (M), and per detection (frame, marker id, is wall, initially inlier)."""
    P, uv, fi, di, dets = [], [], [], [], []
    poses, stamps, odom = [], [], []
    for f, s in zip(frames, seeds):
        if s is None:
            continue
        k = len(poses)
        poses.append(s[0])
        stamps.append(f.stamp)
        odom.append(f.odom)
        seen = [d.id for d in f.detections]
        for d in f.detections:
            if not fld.has_marker(d.id) or seen.count(d.id) > 1:
                continue
            m = fld.marker(d.id)
            c = np.asarray(d.corners, dtype=float).reshape(4, 2)
            if not np.all(np.isfinite(c)):
                continue
            j = len(dets)
            dets.append((k, d.id, m.kind == "wall", d.id in s[1]))
            P.append(m.corners)
            uv.append(c)
            fi.extend([k] * 4)
            di.extend([j] * 4)
    if not dets:
        return None
    return (np.concatenate(P), np.concatenate(uv), np.array(fi), np.array(di), dets,
            np.array(poses, dtype=float), np.array(stamps, dtype=float), odom)


def _odometry_links(odom: list, stamps: np.ndarray, cfg: CalibrationConfig) -> list[tuple[int, int, tuple, np.ndarray]]:
    """(i, j, relative odometry motion, its sigmas) for consecutive frames that both have odometry."""
    links = []
    for i in range(len(odom) - 1):
        a, b = odom[i], odom[i + 1]
        if a is None or b is None or not (0 <= stamps[i + 1] - stamps[i] <= cfg.odom_max_gap_s):
            continue
        d = between2(a, b)
        dist = math.hypot(d[0], d[1])
        dt = max(float(stamps[i + 1] - stamps[i]), 1e-3)
        k = math.sqrt(2) * cfg.stamp_sigma_s / dt  # both stamps uncertain, motion at the link's mean speed
        sxy = cfg.odom_sigma_xy_m + cfg.odom_sigma_xy_per_m * dist + k * dist
        sth = math.radians(cfg.odom_sigma_theta_deg) + cfg.odom_sigma_theta_per_rad * abs(d[2]) + k * abs(d[2])
        links.append((i, i + 1, d, np.array([sxy, sxy, sth])))
    return links


def calibrate(frames: Iterable[FrameData], fld: Field, robot: RobotSpec, cfg: CalibrationConfig | None = None,
              initial: CameraSpec | None = None) -> CalibrationResult:
    """The joint fit (see the module doc). ``robot.camera`` (or ``initial``) is the starting camera and the
    centre of the weak prior. Raises :class:`ConfigError` when the data are too few."""
    from scipy.optimize import least_squares
    from scipy.sparse import coo_matrix

    cfg = cfg or CalibrationConfig()
    cfg.check()
    frames = [f for f in frames if f.detections]
    cam0 = initial or robot.camera
    n_det = sum(1 for f in frames for d in f.detections if fld.has_marker(d.id))
    if len(frames) < cfg.min_frames or n_det < cfg.min_detections:
        raise ConfigError(f"calibration needs at least {cfg.min_frames} frames with markers and "
                          f"{cfg.min_detections} detections of the field's markers; got {len(frames)} frames and "
                          f"{n_det} detections (drive the robot round the field, walls in view)")
    seeds = _seed_poses(frames, fld, replace(robot, camera=cam0))
    stacked = _stack_frames(frames, seeds, fld)
    if stacked is None:
        raise ConfigError("calibration: no frame gave a first pose estimate with the initial camera (is the "
                          "field right, --field, and the initial camera roughly right, --robot?)")
    P, uv, fi, di, dets, poses, stamps, odom = stacked
    nF = len(poses)
    if nF < cfg.min_frames:
        raise ConfigError(f"calibration: only {nF} frames gave a first pose estimate (at least {cfg.min_frames} "
                          f"needed); the initial camera may be far off")
    links = _odometry_links(odom, stamps, cfg)
    notes = []
    free = list(dict.fromkeys(cfg.free))
    if cfg.fit_distortion:
        free += [t for t in cfg.distortion_terms if t not in free]
    if cfg.fit_corner_bias and "corner_bias_px" not in free:
        free.append("corner_bias_px")
    if cfg.fit_forward and links and "x" not in free:
        free.append("x")
    if ("x" in free or cfg.fit_forward) and not links:
        if "x" in free:
            free.remove("x")
        notes.append("no odometry: the forward offset x is held at its initial value (not observable)")
    fidx = [PARAMS.index(k) for k in free]
    LI = np.array([q[0] for q in links], dtype=int)
    LJ = np.array([q[1] for q in links], dtype=int)
    LD = np.array([q[2] for q in links], dtype=float).reshape(-1, 3)
    LS = np.array([q[3] for q in links], dtype=float).reshape(-1, 3)
    v0 = camera_vector(cam0)
    prior_sig = np.array([_prior_sigma(k, cam0, cfg) for k in free])
    # the aspect prior's row: log(fy / fx) against the initial camera's, when both are free
    aspect = ((free.index("fx"), free.index("fy")) if cfg.aspect_sigma > 0 and "fx" in free and "fy" in free
              else None)
    n_asp = 1 if aspect else 0
    nC = len(fidx)
    n_det_all = len(dets)
    inlier = np.array([d[3] for d in dets], dtype=bool)

    def unpack(z):
        v = v0.copy()
        v[fidx] = z[:nC]
        return v, z[nC:].reshape(nF, 3)

    def build(active_corners: np.ndarray):
        Pa, uva, fia = P[active_corners], uv[active_corners], fi[active_corners]
        M = len(Pa)

        def fun(z):
            v, ps = unpack(z)
            pred, Z = predict_corners(v, ps, Pa, fia)
            r = ((pred - uva) / cfg.sigma_px).ravel()
            r = np.where(np.repeat(Z, 2) > 1e-3, r, 1e3)
            out = [r]
            if links:
                a, b = ps[LI], ps[LJ]
                c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
                dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
                lr = np.stack([c * dx + s * dy - LD[:, 0], -s * dx + c * dy - LD[:, 1],
                               wrap_angle(b[:, 2] - a[:, 2] - LD[:, 2])], axis=1) / LS
                out.append(lr.ravel())
            out.append((z[:nC] - v0[fidx]) / prior_sig)
            if aspect:
                ix, iy = aspect
                out.append([(math.log(z[iy] / z[ix]) - math.log(cam0.fy / cam0.fx)) / cfg.aspect_sigma])
            return np.concatenate(out)

        n_rows = 2 * M + 3 * len(links) + nC + n_asp
        r_i, c_i = [], []
        rows = np.arange(2 * M)
        r_i.append(np.repeat(rows, nC))  # every corner: the camera block
        c_i.append(np.tile(np.arange(nC), 2 * M))
        pose_col = nC + 3 * np.repeat(fia, 2)  # and its frame's pose
        for k in range(3):
            r_i.append(rows)
            c_i.append(pose_col + k)
        for q, (i, j, _, _) in enumerate(links):
            rr = np.repeat(2 * M + 3 * q + np.arange(3), 6)
            cc = np.tile(np.concatenate([nC + 3 * i + np.arange(3), nC + 3 * j + np.arange(3)]), 3)
            r_i.append(rr)
            c_i.append(cc)
        r_i.append(2 * M + 3 * len(links) + np.arange(nC))
        c_i.append(np.arange(nC))
        if aspect:
            r_i.append(np.full(2, 2 * M + 3 * len(links) + nC))
            c_i.append(np.array(aspect))
        # the Jacobian's sparsity: the coordinates of ``jac``'s values, block by block in the order it fills them
        J_rows, J_cols = np.concatenate(r_i), np.concatenate(c_i)

        def corner_residuals(v, ps):
            pred, _ = predict_corners(v, ps, Pa, fia)
            return ((pred - uva) / cfg.sigma_px).ravel()

        def jac(z):
            """Camera columns by central differences (one projection of all corners each), pose columns by
            central differences of every frame's pose at once (a corner depends on its own frame only),
            odometry and prior rows analytically."""
            v, ps = unpack(z)
            data = []
            Jc = np.empty((2 * M, nC))
            for k, idx in enumerate(fidx):
                h = 1e-6 * max(1.0, abs(v[idx]))
                vp, vm = v.copy(), v.copy()
                vp[idx] += h
                vm[idx] -= h
                Jc[:, k] = (corner_residuals(vp, ps) - corner_residuals(vm, ps)) / (2 * h)
            data.append(Jc.ravel())
            for k in range(3):
                h = 1e-7
                pp, pm = ps.copy(), ps.copy()
                pp[:, k] += h
                pm[:, k] -= h
                data.append((corner_residuals(v, pp) - corner_residuals(v, pm)) / (2 * h))
            if links:
                a, b = ps[LI], ps[LJ]
                c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
                dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
                r0, r1 = c * dx + s * dy, -s * dx + c * dy
                L = len(links)
                blk = np.zeros((L, 3, 6))  # rows r0, r1, r2; columns xa, ya, tha, xb, yb, thb
                blk[:, 0, 0], blk[:, 0, 1], blk[:, 0, 2], blk[:, 0, 3], blk[:, 0, 4] = -c, -s, r1, c, s
                blk[:, 1, 0], blk[:, 1, 1], blk[:, 1, 2], blk[:, 1, 3], blk[:, 1, 4] = s, -c, -r0, -s, c
                blk[:, 2, 2], blk[:, 2, 5] = -1.0, 1.0
                blk /= LS[:, :, None]
                data.append(blk.ravel())
            data.append(1.0 / prior_sig)
            if aspect:
                ix, iy = aspect
                data.append(np.array([-1.0 / z[ix], 1.0 / z[iy]]) / cfg.aspect_sigma)
            return coo_matrix((np.concatenate(data), (J_rows, J_cols)), shape=(n_rows, nC + 3 * nF)).tocsr()

        fun.jac = jac
        return fun, n_rows, M

    z = np.concatenate([v0[fidx], poses.ravel()])
    res = None
    n_rounds = max(1, cfg.rounds)
    for rnd in range(n_rounds):
        frame_has = np.zeros(nF, dtype=bool)
        frame_has[[dets[j][0] for j in np.flatnonzero(inlier)]] = True
        active_corners = inlier[di] & frame_has[fi]
        fun, n_rows, M = build(active_corners)
        # Huber's threshold follows the residuals down: far from the solution (a camera several pixels off)
        # every residual would be "an outlier" and the robust model stalls the trust region
        r_now = fun(z)[:2 * M]
        f_scale = max(cfg.huber_sigmas, 3.0 * 1.4826 * float(np.median(np.abs(r_now)))) if M else cfg.huber_sigmas
        res = least_squares(fun, z, jac=fun.jac, method="trf", loss="huber", f_scale=f_scale,
                            x_scale="jac", max_nfev=cfg.max_nfev, xtol=1e-10, ftol=1e-10,
                            tr_options={"atol": 1e-12, "btol": 1e-12, "maxiter": 4000}, verbose=0)
        z = res.x
        # re-decide every detection of the seeded frames with the new camera and poses
        v, ps = unpack(z)
        pred, Z = predict_corners(v, ps, P, fi)
        e = pred - uv
        per_det = np.sqrt(np.bincount(di, weights=np.sum(e ** 2, axis=1), minlength=n_det_all) / 4)
        behind = np.bincount(di, weights=(Z <= 1e-3).astype(float), minlength=n_det_all) > 0
        scale = 1.4826 * float(np.median(np.abs(e[inlier[di]]))) if inlier.any() else cfg.sigma_px
        limit = max(cfg.outlier_px, cfg.outlier_scales * scale)
        new = (per_det <= limit) & ~behind
        if np.array_equal(new, inlier) and f_scale <= cfg.huber_sigmas:
            break
        if rnd == n_rounds - 1:  # report on the set last fitted
            notes.append(f"outlier rejection had not settled after {n_rounds} rounds "
                         f"({int(np.count_nonzero(new != inlier))} detections would still change)")
            break
        inlier = new
    v, ps = unpack(z)
    pred, _ = predict_corners(v, ps, P[active_corners], fi[active_corners])
    resid = pred - uv[active_corners]
    cov_c = _camera_covariance(res, nC, n_rows=n_rows, n_params=len(z))
    sig = {k: float(math.sqrt(max(cov_c[i, i], 0.0))) for i, k in enumerate(free)}
    degenerate = tuple(k for i, k in enumerate(free) if sig[k] > cfg.degenerate_ratio * prior_sig[i])
    corr = {}
    d = np.sqrt(np.maximum(np.diag(cov_c), 1e-300))
    R = cov_c / np.outer(d, d)
    pairs = sorted(((abs(R[i, j]), i, j) for i in range(nC) for j in range(i + 1, nC)), reverse=True)[:4]
    for _, i, j in pairs:
        corr[f"{free[i]}/{free[j]}"] = float(R[i, j])
    walls = sum(1 for j in np.flatnonzero(inlier) if dets[j][2] and frame_has[dets[j][0]])
    used = int(np.count_nonzero(inlier & frame_has[[d[0] for d in dets]]))
    if walls == 0:
        notes.append("no wall markers: focal length, height and pitch are not separable from floor markers alone")
    if degenerate:
        notes.append(f"poorly determined by these data (sigma above {cfg.degenerate_ratio:g} of the prior's): "
                     f"{', '.join(degenerate)}")
    dist = np.linalg.norm(resid, axis=1)
    return CalibrationResult(
        camera=camera_from_vector(cam0, v), initial=cam0, free=tuple(free), sigma=sig,
        residual_px_rms=float(np.sqrt(np.mean(resid ** 2))) if len(resid) else float("nan"),
        residual_px_median=float(np.median(dist)) if len(dist) else float("nan"),
        frames=int(frame_has.sum()), detections=used, rejected=int(n_det_all - np.count_nonzero(inlier)),
        frames_dropped=int(len(frames) - frame_has.sum()), wall_detections=int(walls),
        floor_detections=int(used - walls), odometry_links=len(links), degenerate=degenerate, correlation=corr,
        poses=ps[frame_has].copy(), stamps=stamps[frame_has].copy(), residuals=resid,
        points_px=uv[active_corners].copy(), cost=float(res.cost), nfev=int(res.nfev), notes=tuple(notes),
        corner_bias_px=float(v[14]))


def _prior_sigma(name: str, cam: CameraSpec, cfg: CalibrationConfig) -> float:
    s = float(cfg.prior_sigma.get(name, 1.0))
    if name in ("fx", "fy"):
        return s * (cam.fx if name == "fx" else cam.fy)
    if name in ("cx", "cy"):
        return s * cam.width
    return s


def _camera_covariance(res, nC: int, n_rows: int, n_params: int) -> np.ndarray:
    """Covariance of the camera block: the camera rows and columns of the inverse of J^T J (Huber-weighted,
    camera and poses together, so the poses' uncertainty is accounted for), scaled by the a-posteriori variance
    factor 2*cost/(m - n). J^T J is sparse (the camera's rows and columns, 3x3 pose blocks, odometry between
    neighbours): a sparse LU solves for the camera's columns only."""
    from scipy.sparse import csc_matrix, identity
    from scipy.sparse.linalg import splu

    dof = max(1, n_rows - n_params)
    s2 = max(2.0 * float(res.cost) / dof, 1e-12)
    if nC == 0:
        return np.zeros((0, 0))
    J = csc_matrix(res.jac)
    H = (J.T @ J).tocsc()
    n = H.shape[0]
    E = np.zeros((n, nC))
    E[np.arange(nC), np.arange(nC)] = 1.0
    try:
        X = splu(H).solve(E)
    except RuntimeError:  # singular: a tiny ridge (the prior rows normally prevent this)
        X = splu((H + 1e-9 * identity(n, format="csc")).tocsc()).solve(E)
    C = X[:nC] * s2
    return 0.5 * (C + C.T)


# ------------------------------------------------------------------------------------ recorded data


def interpolate_odometry(odom: Sequence[tuple[float, float, float, float]], stamps: Sequence[float],
                         max_gap_s: float = 0.5) -> list[tuple[float, float, float] | None]:
    """Odometry (t, x, y, theta rows, oldest first) linearly interpolated at each stamp; None outside the
    recorded span or where the neighbouring messages are more than ``max_gap_s`` apart."""
    if not len(odom):
        return [None] * len(stamps)
    a = np.asarray(odom, dtype=float).reshape(-1, 4)
    a = a[np.argsort(a[:, 0], kind="stable")]
    t = a[:, 0]
    th = np.unwrap(a[:, 3])
    out = []
    for s in stamps:
        i = int(np.searchsorted(t, s))
        if i == 0 or i >= len(t):
            out.append(tuple(a[i, 1:]) if i < len(t) and abs(t[i] - s) < 1e-6 else None)
            continue
        if t[i] - t[i - 1] > max_gap_s:
            out.append(None)
            continue
        f = (s - t[i - 1]) / max(t[i] - t[i - 1], 1e-12)
        out.append((float(a[i - 1, 1] + f * (a[i, 1] - a[i - 1, 1])),
                    float(a[i - 1, 2] + f * (a[i, 2] - a[i - 1, 2])),
                    float(wrap_angle(th[i - 1] + f * (th[i] - th[i - 1])))))
    return out
