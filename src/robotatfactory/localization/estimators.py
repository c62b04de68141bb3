"""Camera and robot pose from one frame's marker observations, three ways, each with a covariance.

- :func:`closest_marker`: the paper's method, the camera pose from the closest marker only,
  ``T_world_cam = T_world_marker @ inv(T_cam_marker)``; with ``checked=False`` IPPE's best solution (as the
  paper), with ``checked=True`` the solution the camera-mount check picks.
- :func:`all_markers_pnp`: one PnP (SQPnP, then Levenberg-Marquardt) over the corners of every visible marker
  with their world coordinates; 6 degrees of freedom, then checked against the mount.
- :func:`planar_fit`: (x, y, heading) of ``base_link`` by Gauss-Newton/LM on the reprojection error of all
  corners, the camera mount fixed (3 degrees of freedom); seeded by the mount-valid IPPE solutions of the
  closest markers (and the filter's prior if given); markers that disagree are dropped one at a time.

Covariances are first order: ``(J^T W J)^-1`` with ``J`` the Jacobian of the corner pixels with respect to the
pose and ``W`` the inverse corner variances of the noise model (:meth:`PoseConfig.corner_sigma`, which grows
with the marker's distance and the obliquity of the view), scaled up by the a-posteriori variance factor when
the residuals are larger than the model says, plus a small model-error floor. The planar covariance is of
(x, y, heading) of ``base_link`` in ``map``; the 6-DoF covariance is of the camera pose perturbed in the world
frame (x, y, z, then rotations about the world x, y, z axes; ROS's PoseWithCovariance order).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..field.model import Field
from . import reasons
from .geometry import inv, matrix_rt, matrix_se2, rt_matrix, se2_matrix, wrap_angle
from .markerpose import MarkerObservation, PoseConfig, mount_check


@dataclass
class PoseEstimate:
    """The result of one method on one frame. ``ok`` False means rejected, ``reason`` says why."""

    method: str
    ok: bool
    reason: str | None = None
    base: tuple[float, float, float] | None = None  # base_link (x, y, heading) in map, m and rad
    cov: np.ndarray | None = None  # 3x3 covariance of base (x, y, heading)
    T_world_cam: np.ndarray | None = None  # camera_optical in map
    cov6: np.ndarray | None = None  # 6x6 covariance of the camera pose (see module doc)
    marker_ids: tuple[int, ...] = ()
    n_corners: int = 0
    rms_px: float = float("nan")
    closest_m: float = float("nan")
    mount_height_m: float = float("nan")
    mount_tilt_deg: float = float("nan")
    dropped: tuple[int, ...] = ()  # markers dropped as outliers

    @property
    def sigma_xy(self) -> float:
        return math.sqrt(max(0.0, 0.5 * (self.cov[0, 0] + self.cov[1, 1]))) if self.cov is not None else math.inf

    @property
    def sigma_theta(self) -> float:
        return math.sqrt(max(0.0, self.cov[2, 2])) if self.cov is not None else math.inf


def _fail(method: str, reason: str, **kw) -> PoseEstimate:
    return PoseEstimate(method, False, reason, **kw)


# ----------------------------------------------------------------------------------------------- 6-DoF


def _jac6(T_wc: np.ndarray, P: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (2N) and their Jacobian (2N x 6) w.r.t. a world-frame perturbation (dt, dphi) of T_world_cam:
    t' = t + dt, R' = Exp(dphi) R."""
    R_cw = T_wc[:3, :3].T
    q = P - T_wc[:3, 3]
    pc = q @ R_cw.T
    X, Y, Z = pc[:, 0], pc[:, 1], pc[:, 2]
    fx, fy = K[0, 0], K[1, 1]
    iz = 1.0 / Z
    u = fx * X * iz + K[0, 2]
    v = fy * Y * iz + K[1, 2]
    n = len(P)
    # d pc / d dt = -R_cw (same for all points); d pc / d dphi = R_cw [q]x  (per point)
    qx = np.zeros((n, 3, 3))
    qx[:, 0, 1], qx[:, 0, 2], qx[:, 1, 2] = -q[:, 2], q[:, 1], -q[:, 0]
    qx[:, 1, 0], qx[:, 2, 0], qx[:, 2, 1] = q[:, 2], -q[:, 1], q[:, 0]
    D = np.empty((n, 3, 6))
    D[:, :, :3] = -R_cw
    D[:, :, 3:] = np.einsum("ij,njk->nik", R_cw, qx)
    J = np.empty((2 * n, 6))
    J[0::2] = fx * (D[:, 0, :] - (X * iz)[:, None] * D[:, 2, :]) * iz[:, None]
    J[1::2] = fy * (D[:, 1, :] - (Y * iz)[:, None] * D[:, 2, :]) * iz[:, None]
    return np.stack([u, v], axis=1).ravel(), J


def _exp_left(T: np.ndarray, d: np.ndarray) -> np.ndarray:
    out = T.copy()
    out[:3, :3] = cv2.Rodrigues(np.asarray(d[3:], dtype=float).reshape(3, 1))[0] @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + d[:3]
    return out


def _cov_from_jac(J: np.ndarray, r: np.ndarray, sig: np.ndarray, n_params: int) -> tuple[np.ndarray, float]:
    """(J^T W J)^-1 scaled by max(1, chi2/dof); returns (cov, chi2)."""
    Wj = J / sig[:, None]
    A = Wj.T @ Wj
    chi2 = float(np.sum((r / sig) ** 2))
    dof = len(r) - n_params
    try:
        cov = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(A)
    if dof > 0:
        cov = cov * max(1.0, chi2 / dof)
    return 0.5 * (cov + cov.T), chi2


def _planar_from_cam(T_wc: np.ndarray, cov6: np.ndarray, T_cam_base: np.ndarray) -> tuple[tuple, np.ndarray]:
    """base (x, y, heading) of a camera pose and its 3x3 covariance (first order, through the same
    world-frame perturbation as :func:`_jac6`)."""
    T_wb = T_wc @ T_cam_base
    base = matrix_se2(T_wb)
    a = T_wc[:3, :3] @ T_cam_base[:3, 3]  # camera -> base offset in the world
    c = T_wb[:3, 0]  # base x axis in the world
    G = np.zeros((3, 6))
    G[0, 0] = G[1, 1] = 1.0
    # d t_b = dt + dphi x a ; rows x, y of -[a]x
    G[0, 3:] = [0.0, a[2], -a[1]]
    G[1, 3:] = [-a[2], 0.0, a[0]]
    # d c = dphi x c ; yaw = atan2(c_y, c_x)
    dcx = np.array([0.0, c[2], -c[1]])
    dcy = np.array([-c[2], 0.0, c[0]])
    h2 = c[0] ** 2 + c[1] ** 2
    G[2, 3:] = (c[0] * dcy - c[1] * dcx) / max(h2, 1e-12)
    return base, G @ cov6 @ G.T


def _stack(obs: list[MarkerObservation]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    P = np.concatenate([o.marker.corners for o in obs])
    uv = np.concatenate([o.corners for o in obs])
    sig = np.repeat([o.sigma_px for o in obs], 8)
    return P, uv, sig


def _finish6(method: str, T_wc: np.ndarray, obs: list[MarkerObservation], K: np.ndarray,
             T_cam_base: np.ndarray, cfg: PoseConfig, check_mount: bool) -> PoseEstimate:
    ids = tuple(o.id for o in obs)
    closest = min(o.distance_m for o in obs)
    if not np.all(np.isfinite(T_wc)):
        return _fail(method, reasons.NOT_FINITE, marker_ids=ids)
    P, uv, sig = _stack(obs)
    pred, J = _jac6(T_wc, P, K)
    r = pred - uv.ravel()
    rms = float(np.sqrt(np.mean(r ** 2)))
    cov6, _ = _cov_from_jac(J, r, sig, 6)
    base, cov = _planar_from_cam(T_wc, cov6, T_cam_base)
    mc = mount_check(T_wc, T_cam_base, cfg)
    est = PoseEstimate(method, True, None, base, cov, T_wc, cov6, ids, len(P), rms, closest, mc.height_m,
                       math.degrees(mc.tilt_rad))
    if check_mount and not mc.ok:
        est.ok, est.reason = False, reasons.MOUNT_CHECK
    return est


def closest_marker(obs: list[MarkerObservation], field: Field, K: np.ndarray, T_cam_base: np.ndarray,
                   cfg: PoseConfig, checked: bool = False) -> PoseEstimate:
    """The paper's method: the camera pose from the closest marker. ``checked=False``: IPPE's best solution
    and no rejection at all (exactly the paper); ``checked=True``: the mount-checked solution and
    :func:`sanity`."""
    method = "closest_checked" if checked else "closest"
    if not obs:
        return _fail(method, reasons.NO_MARKERS)
    o = min(obs, key=lambda o: o.distance_m)
    if checked:
        if o.checked is None:
            return _fail(method, reasons.MOUNT_CHECK, marker_ids=(o.id,), closest_m=o.distance_m)
        i = o.checked
    else:
        i = 0
    est = _finish6(method, o.T_world_cam(i), [o], K, T_cam_base, cfg, check_mount=checked)
    return est if not checked else sanity(est, field, cfg)


def all_markers_pnp(obs: list[MarkerObservation], field: Field, K: np.ndarray, T_cam_base: np.ndarray,
                    cfg: PoseConfig) -> PoseEstimate:
    """One PnP over the corners of all markers: SQPnP (any configuration), refined by Levenberg-Marquardt;
    with one marker, or if SQPnP's answer fails the mount check, the refinement also starts from the
    mount-checked IPPE solutions and the lowest-error mount-valid result wins."""
    method = "all_pnp"
    if not obs:
        return _fail(method, reasons.NO_MARKERS)
    P, uv, sig = _stack(obs)
    starts = []
    if len(obs) > 1:
        try:
            ok, rvec, tvec = cv2.solvePnP(P, uv, K, None, flags=cv2.SOLVEPNP_SQPNP)
            if ok:
                starts.append((rvec, tvec))
        except cv2.error:
            pass
    for o in sorted(obs, key=lambda o: o.distance_m)[:cfg.seed_markers]:
        if o.checked is not None:
            starts.append(matrix_rt(inv(o.T_world_cam(o.checked))))
    best = None
    for rvec, tvec in starts:
        try:
            rvec, tvec = cv2.solvePnPRefineLM(P, uv, K, None, rvec.copy(), tvec.copy())
        except cv2.error:
            continue
        T_wc = inv(rt_matrix(rvec, tvec))
        if not np.all(np.isfinite(T_wc)):
            continue
        mc = mount_check(T_wc, T_cam_base, cfg)
        pred = cv2.projectPoints(P, rvec, tvec, K, None)[0].reshape(-1, 2)
        err = float(np.mean((pred - uv) ** 2))
        key = (not mc.ok, err)
        if best is None or key < best[0]:
            best = (key, T_wc)
        if mc.ok and len(obs) > 1 and best[1] is T_wc:
            break  # SQPnP's answer is valid: no need to try the seeds
    if best is None:
        return _fail(method, reasons.PNP_FAILED, marker_ids=tuple(o.id for o in obs))
    return sanity(_finish6(method, best[1], obs, K, T_cam_base, cfg, check_mount=True), field, cfg)


# ---------------------------------------------------------------------------------------------- planar


class PlanarModel:
    """Pixels of world points as a function of the robot's (x, y, heading), the camera mount fixed."""

    def __init__(self, K: np.ndarray, T_base_cam: np.ndarray):
        self.K = K
        T_cb = inv(T_base_cam)
        self.R_cb, self.t_cb = T_cb[:3, :3], T_cb[:3, 3]

    def residuals(self, p: np.ndarray, P: np.ndarray, uv: np.ndarray, jac: bool = True,
                  behind: float | None = None):
        """Residuals (predicted - observed, 2N: u0 v0 u1 v1 ...) and their Jacobian (2N x 3). Points
        behind the camera make the result None, or (with ``behind``, and ``jac`` False) get that value."""
        x, y, th = p
        c, s = math.cos(th), math.sin(th)
        qx, qy = P[:, 0] - x, P[:, 1] - y
        bx, by = c * qx + s * qy, -s * qx + c * qy  # base-frame points (z unchanged)
        R, t = self.R_cb, self.t_cb
        X = R[0, 0] * bx + R[0, 1] * by + R[0, 2] * P[:, 2] + t[0]
        Y = R[1, 0] * bx + R[1, 1] * by + R[1, 2] * P[:, 2] + t[1]
        Z = R[2, 0] * bx + R[2, 1] * by + R[2, 2] * P[:, 2] + t[2]
        bad = Z < 1e-3
        anybad = bool(bad.any())
        if anybad and (behind is None or jac):
            return None, None
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        iz = 1.0 / np.where(bad, 1.0, Z) if anybad else 1.0 / Z
        n = len(P)
        r = np.empty((n, 2))
        r[:, 0] = fx * X * iz + cx - uv[:, 0]
        r[:, 1] = fy * Y * iz + cy - uv[:, 1]
        if anybad:
            r[bad] = behind
        r = r.reshape(-1)
        if not jac:
            return r, None
        # d(base point)/dx = (-c, s, 0), /dy = (-s, -c, 0), /dth = (by, -bx, 0); camera = R @ base
        dX = np.empty((n, 3))
        dY = np.empty((n, 3))
        dZ = np.empty((n, 3))
        for row, out in ((0, dX), (1, dY), (2, dZ)):
            a, b = R[row, 0], R[row, 1]
            out[:, 0] = -a * c + b * s
            out[:, 1] = -a * s - b * c
            out[:, 2] = a * by - b * bx
        J = np.empty((2 * n, 3))
        J[0::2] = fx * (dX - (X * iz)[:, None] * dZ) * iz[:, None]
        J[1::2] = fy * (dY - (Y * iz)[:, None] * dZ) * iz[:, None]
        return r, J


def _lm(model: PlanarModel, p0: np.ndarray, P: np.ndarray, uv: np.ndarray, sig: np.ndarray,
        iters: int = 20) -> tuple[np.ndarray, float] | None:
    """Weighted Levenberg-Marquardt from p0; returns (p, chi2) or None if the start is invalid."""
    p = np.array(p0, dtype=float)
    r, J = model.residuals(p, P, uv)
    if r is None:
        return None
    w = 1.0 / sig
    cost = float(np.sum((r * w) ** 2))
    lam = 1e-3
    for _ in range(iters):
        Jw = J * w[:, None]
        A = Jw.T @ Jw
        g = Jw.T @ (r * w)
        try:
            dp = -np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), g)
        except np.linalg.LinAlgError:
            return None
        pn = p + dp
        pn[2] = wrap_angle(pn[2])
        rn, Jn = model.residuals(pn, P, uv)
        cn = float(np.sum((rn * w) ** 2)) if rn is not None else math.inf
        if cn < cost:
            # converged: the step is far below any accuracy we claim (1 um, 1 urad), or the cost stalls
            small = abs(cost - cn) < 1e-6 * max(cost, 1e-12) or (abs(dp[0]) + abs(dp[1]) < 1e-6 and abs(dp[2]) < 1e-6)
            p, r, J, cost = pn, rn, Jn, cn
            lam = max(lam / 10, 1e-9)
            if small:
                break
        else:
            lam *= 10
            if lam > 1e6:
                break
    return p, cost


def hypotheses(obs: list[MarkerObservation], T_cam_base: np.ndarray,
               prior: tuple[float, float, float] | None = None) -> list[np.ndarray]:
    """Candidate robot poses (x, y, heading): the prior, then every marker's mount-valid IPPE solutions
    (closest markers first)."""
    seeds = []
    if prior is not None and all(math.isfinite(v) for v in prior):
        seeds.append(np.array(prior, dtype=float))
    for o in sorted(obs, key=lambda o: o.distance_m):
        for i, mc in enumerate(o.mount):
            if mc.ok:
                seeds.append(np.array(matrix_se2(o.T_world_cam(i) @ T_cam_base)))
    return seeds


def consensus(obs: list[MarkerObservation], model: PlanarModel, T_cam_base: np.ndarray, cfg: PoseConfig,
              prior: tuple[float, float, float] | None = None) -> tuple[list[MarkerObservation], list[np.ndarray]]:
    """The markers that agree with the best-supported hypothesis (per-marker RMS reprojection error under
    ``cfg.consensus_px``) and the hypotheses ranked by support (more markers, then lower error)."""
    seeds = hypotheses(obs, T_cam_base, prior)
    if len(obs) == 1 or not seeds:
        return list(obs), seeds
    P, uv, _ = _stack(obs)
    n = len(obs)
    scored = []
    for k, s in enumerate(seeds):
        r = model.residuals(s, P, uv, jac=False, behind=np.inf)[0]
        rms = np.sqrt(np.mean(r.reshape(n, 8) ** 2, axis=1))
        inl = rms < cfg.consensus_px
        scored.append((-int(inl.sum()), float(np.sum(np.minimum(rms, cfg.consensus_px) ** 2)), k, inl))
        if inl.all():
            break  # every marker agrees: the least-squares fit takes it from here
    scored.sort(key=lambda x: (x[0], x[1], x[2]))
    best = scored[0][3]
    return [o for o, ok in zip(obs, best) if ok], [seeds[x[2]] for x in scored]


def planar_fit(obs: list[MarkerObservation], field: Field, K: np.ndarray, T_base_cam: np.ndarray,
               cfg: PoseConfig, prior: tuple[float, float, float] | None = None,
               model: PlanarModel | None = None, agreed: tuple | None = None) -> PoseEstimate:
    """(x, y, heading) of base_link with the mount fixed: consensus (``agreed``: a precomputed
    :func:`consensus` result) over the markers' hypotheses, LM from
    the best-supported seeds, outlier markers dropped one at a time (and readmitted if they agree with the
    final fit), then :func:`sanity`."""
    method = "planar"
    if not obs:
        return _fail(method, reasons.NO_MARKERS)
    model = model or PlanarModel(K, T_base_cam)
    T_cam_base = inv(T_base_cam)
    active, seeds = agreed if agreed is not None else consensus(obs, model, T_cam_base, cfg, prior)
    active = list(active)
    if not seeds:
        return _fail(method, reasons.MOUNT_CHECK, marker_ids=tuple(o.id for o in obs),
                     closest_m=min(o.distance_m for o in obs))
    seeds = seeds[:max(1, cfg.refine_seeds)]
    dropped: list[MarkerObservation] = [o for o in obs if o not in active]
    readmitted = False
    while True:
        P, uv, sig = _stack(active)
        best = None
        uniq: list[np.ndarray] = []
        good_chi2 = cfg.marker_outlier_chi2 * len(active) / 2
        for s in seeds:
            if any(abs(s[0] - u[0]) + abs(s[1] - u[1]) < 1e-3 and abs(wrap_angle(s[2] - u[2])) < 1e-3 for u in uniq):
                continue
            uniq.append(s)
            res = _lm(model, s, P, uv, sig)
            if res is not None and (best is None or res[1] < best[1]):
                best = res
            if best is not None and best[1] < good_chi2:
                break  # a good fit: the other seeds could only find the same minimum
        if best is None:
            return _fail(method, reasons.NOT_FINITE, marker_ids=tuple(o.id for o in active))
        p, chi2 = best
        r, J = model.residuals(p, P, uv)
        per_marker = np.sum(((r / sig) ** 2).reshape(len(active), 8), axis=1)
        worst = int(np.argmax(per_marker))
        if per_marker[worst] > cfg.marker_outlier_chi2 and len(active) > 1:
            dropped.append(active.pop(worst))
            seeds = [p]
            continue
        if dropped and not readmitted:
            readmitted = True
            back = []
            for o in dropped:
                ro = model.residuals(p, o.marker.corners, o.corners, jac=False)[0]
                if ro is not None and float(np.sum((ro / o.sigma_px) ** 2)) <= cfg.marker_outlier_chi2:
                    back.append(o)
            if back:
                active += back
                dropped = [o for o in dropped if o not in back]
                seeds = [p]
                continue
        break
    ids = tuple(o.id for o in active)
    closest = min(o.distance_m for o in active)
    rms = float(np.sqrt(np.mean(r ** 2)))
    cov, _ = _cov_from_jac(J, r, sig, 3)
    fp, fh = cfg.floor_position_sigma_m, math.radians(cfg.floor_heading_sigma_deg)
    cov = cov + np.diag([fp ** 2, fp ** 2, fh ** 2])
    base = (float(p[0]), float(p[1]), float(wrap_angle(p[2])))
    T_wc = se2_matrix(*base) @ T_base_cam
    est = PoseEstimate(method, True, None, base, cov, T_wc, None, ids, len(P), rms, closest, 0.0, 0.0,
                       tuple(o.id for o in dropped))
    return sanity(est, field, cfg, n_markers=len(active), per_marker_chi2=float(per_marker[worst]))


def sanity(est: PoseEstimate, field: Field, cfg: PoseConfig, n_markers: int | None = None,
           per_marker_chi2: float = 0.0) -> PoseEstimate:
    """Reject absurd or unreliable estimates in place (and return it)."""
    if not est.ok:
        return est
    n_markers = len(est.marker_ids) if n_markers is None else n_markers
    reason = None
    if est.base is None or not all(math.isfinite(v) for v in est.base) or est.cov is None \
            or not np.all(np.isfinite(est.cov)):
        reason = reasons.NOT_FINITE
    elif n_markers == 1 and per_marker_chi2 > cfg.marker_outlier_chi2:
        reason = reasons.REPROJECTION
    elif est.rms_px > cfg.max_rms_px:
        reason = reasons.REPROJECTION
    elif n_markers == 1 and est.closest_m > cfg.lone_marker_max_distance_m:
        reason = reasons.FAR_LONE_MARKER
    elif not _on_field(est.base, field, cfg.field_margin_m):
        reason = reasons.OUTSIDE_FIELD
    elif _in_wall(est.base, field):
        reason = reasons.INSIDE_WALL
    elif est.sigma_xy > cfg.max_position_sigma_m or est.sigma_theta > math.radians(cfg.max_heading_sigma_deg):
        reason = reasons.UNCERTAIN
    if reason:
        est.ok, est.reason = False, reason
    return est


def _on_field(base, field: Field, margin: float) -> bool:
    a = field.floor
    return a.x[0] - margin <= base[0] <= a.x[1] + margin and a.y[0] - margin <= base[1] <= a.y[1] + margin


def _in_wall(base, field: Field, shrink: float = 0.005) -> bool:
    """Is the robot's centre inside a wall taller than the robot's base (the centre cannot be there)?"""
    for b in field.boxes:
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        dx, dy = base[0] - b.center[0], base[1] - b.center[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        if abs(lx) < b.size[0] / 2 - shrink and abs(ly) < b.size[1] / 2 - shrink:
            return True
    return False
