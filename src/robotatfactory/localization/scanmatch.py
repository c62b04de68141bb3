"""LIDAR scan matching against the field's map: the robot's pose from a 2D scan of the known structures.

The field's boxes that the scan plane cuts (warehouse walls and ribs, the machines' walls and ribs) and its
beacon cylinders are the map (:class:`FieldMap`). A scan's returns, moved into ``base_link`` at one reference
time (:func:`deskew`: the robot moves during a 0.2 s sweep, up to 4 cm and 17 degrees at the agent's speeds),
are fitted to the map by Gauss-Newton on their signed distances to the nearest surface, from the filter's
prior (:meth:`FieldMap.match`): robust (Huber) weights, returns farther than ``outlier_m`` from every mapped
surface left out (parts, other robots, anything the map does not have). The result is an absolute pose with
its covariance (the inverse of the fit's information, inflated by ``rays_per_independent`` because
neighbouring returns share the map's and the mount's errors), a fix for the EKF like a camera fix. Where the
returns constrain a direction only weakly (a straight wall alone) the covariance says so along that
direction: the filter's update then corrects the rest (heading and the distance to the wall).

Why: the camera gives no absolute heading where no marker is readable (SimTwo's outgoing warehouse shows
none, docs/simtwo.md "The agent on SimTwo"), while the LIDAR sees the warehouse's wall and ribs there.

Plain Python (numpy), no ROS. Lengths in metres, angles in radians, poses (x, y, heading).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from ..settings import setting
from .geometry import wrap_angle


@dataclass(frozen=True)
class ScanMatchConfig:
    """Settings of the scan matching (``scan_match.*``)."""

    enabled: bool = setting(True, "scan fixes for the EKF, the field's boxes as the map (docs/localization.md, "
                                  "\"LIDAR scan matching\")")
    stride: int = setting(2, "use every n-th ray (360 rays: up to 180 returns)", lo=1)
    dense_when_few: bool = setting(True, "when every stride-th ray gives fewer than min_points returns, every ray "
                                          "(the fit's covariance then times stride more: the same surfaces); where "
                                          "one wall is all the LIDAR sees past the robot and a held part")
    dense_when_few_on_map: bool = setting(True, "when the fit of every stride-th ray has fewer than min_points "
                                                "returns on the map (too_few_on_map), it is tried again with "
                                                "every ray, the covariance as for dense_when_few")
    max_range_m: float = setting(1.5, "m: farther returns are not used (the range noise grows with distance)",
                                 lo=0.0, lo_open=True)
    body_margin_m: float = setting(0.02, "m: returns on the robot or a held part (their outline grown by this) "
                                         "are ignored", lo=0.0)
    min_points: int = setting(30, "fewest returns on mapped surfaces for a fix", lo=1)
    min_inlier_share: float = setting(0.5, "... and at least this share of the usable returns", lo=0.0, hi=1.0,
                                      lo_open=True)
    outlier_m: float = setting(0.015, "m: a return farther than this (or 3 sigma) from every mapped surface after "
                                      "the fit is something the map does not have (a part, a robot): left out",
                               lo=0.0, lo_open=True)
    huber_m: float = setting(0.005, "m, robust weight: returns farther than this (or 1 sigma) count less", lo=0.0,
                             lo_open=True)
    sigma_m: float = setting(0.003, "m, the least error of one return (the map's and the mount's); the LIDAR's "
                                    "range noise (the robot file's lidar noise_a, noise_b) adds to it", lo=0.0,
                             lo_open=True)
    rays_per_independent: float = setting(8.0, "neighbouring returns share the map's and the mount's errors: the "
                                               "fit's covariance times this", lo=0.0, lo_open=True)
    max_rms_sigmas: float = setting(2.0, "a fit whose inliers' RMS distance exceeds this many sigmas is not used",
                                    lo=0.0, lo_open=True)
    max_correction_m: float = setting(0.06, "m: a fit this far from the filter's pose found another basin: not "
                                            "used", lo=0.0, lo_open=True)
    max_correction_deg: float = setting(6.0, "deg: ... or this far in heading", lo=0.0, hi=180.0, lo_open=True)
    max_iterations: int = setting(15, "most Gauss-Newton iterations of one fit", lo=1)


@dataclass
class ScanFix:
    """The outcome of one match: ``ok`` with ``pose`` (base_link in map at ``t``) and ``cov`` (3x3), or the
    ``reason`` it is not used."""

    ok: bool
    t: float = math.nan
    pose: tuple[float, float, float] | None = None
    cov: np.ndarray | None = None
    reason: str = ""
    points: int = 0
    inliers: int = 0
    rms_m: float = math.nan
    iterations: int = 0
    every_ray: bool = False  # fitted with every ray (dense_when_few, dense_when_few_on_map), not every stride-th


def _se2(p) -> np.ndarray:
    c, s = math.cos(p[2]), math.sin(p[2])
    return np.array([[c, -s, p[0]], [s, c, p[1]], [0.0, 0.0, 1.0]])


def _laser_in_map(x, laser_xy) -> tuple[float, float]:
    c, s = math.cos(x[2]), math.sin(x[2])
    return x[0] + c * laser_xy[0] - s * laser_xy[1], x[1] + s * laser_xy[0] + c * laser_xy[1]


def _pose(T: np.ndarray) -> tuple[float, float, float]:
    return float(T[0, 2]), float(T[1, 2]), math.atan2(T[1, 0], T[0, 0])


class FieldMap:
    """The surfaces a LIDAR at height ``scan_z`` sees: the field's boxes the plane cuts and its beacons."""

    def __init__(self, field, scan_z: float, beacons: bool = True):
        rows = [b.plan for b in field.boxes_at_height(scan_z)]
        self.boxes = np.array(rows, dtype=float).reshape(-1, 6)
        circ = []
        if beacons and field.beacons and scan_z <= field.beacon_height:
            circ = [(x, y, field.beacon_diameter / 2) for x, y in field.beacons]
        self.circles = np.array(circ, dtype=float).reshape(-1, 3)
        self.faces = self._faces()
        if not len(self.boxes) and not len(self.circles):
            raise ValueError(f"field {field.name}: nothing at the LIDAR's height {scan_z} m to match a scan against")

    def _faces(self) -> np.ndarray:
        """The boxes' faces: (centre x, y, outward normal x, y, half length, box index), 4 per box."""
        rows = []
        for k, (cx, cy, hx, hy, c, s) in enumerate(self.boxes):
            for nx, ny, d, half in ((1, 0, hx, hy), (-1, 0, hx, hy), (0, 1, hy, hx), (0, -1, hy, hx)):
                wx, wy = c * nx - s * ny, s * nx + c * ny  # the normal in the map
                rows.append((cx + d * wx, cy + d * wy, wx, wy, half, k))
        return np.array(rows, dtype=float).reshape(-1, 6)

    def distance(self, pts: np.ndarray, origin: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (m) of each point (N x 2, map) to the nearest mapped surface that faces ``origin``
        (the LIDAR: a ray ends on a face turned towards it, never on the back of a 2 cm rib), positive on the
        side the face looks at, and its gradient (N x 2). inf where no face is visible."""
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        n = len(pts)
        best = np.full(n, np.inf)
        grad = np.zeros((n, 2))
        rows = np.arange(n)
        if len(self.faces):
            fx, fy, nx, ny, half = (self.faces[:, k] for k in range(5))
            vis = (origin[0] - fx) * nx + (origin[1] - fy) * ny > 0
            if vis.any():
                fx, fy, nx, ny, half = fx[vis], fy[vis], nx[vis], ny[vis], half[vis]
                dx, dy = pts[:, :1] - fx[None, :], pts[:, 1:] - fy[None, :]
                along = -dx * ny[None, :] + dy * nx[None, :]  # along the face (tangent = normal turned +90 deg)
                normal = dx * nx[None, :] + dy * ny[None, :]
                over = np.abs(along) - half[None, :]
                beyond = over > 0
                dist = np.where(beyond, np.sign(normal) * np.hypot(np.maximum(over, 0.0), normal), normal)
                k = np.argmin(np.abs(dist), axis=1)
                best = dist[rows, k]
                b = beyond[rows, k]
                tx, ty = -ny[k], nx[k]
                sa = np.sign(along[rows, k])
                ex = fx[k] + sa * half[k] * tx  # the face's end nearest the point
                ey = fy[k] + sa * half[k] * ty
                ux, uy = pts[:, 0] - ex, pts[:, 1] - ey
                un = np.maximum(np.hypot(ux, uy), 1e-12)
                sg = np.where(normal[rows, k] >= 0, 1.0, -1.0)
                grad = np.stack([np.where(b, sg * ux / un, nx[k]), np.where(b, sg * uy / un, ny[k])], axis=1)
        if len(self.circles):
            dx = pts[:, :1] - self.circles[None, :, 0]
            dy = pts[:, 1:] - self.circles[None, :, 1]
            r = np.hypot(dx, dy)
            sd = r - self.circles[None, :, 2]
            k = np.argmin(np.abs(sd), axis=1)
            sdk = sd[rows, k]
            rk = np.maximum(r[rows, k], 1e-9)
            better = np.abs(sdk) < np.abs(best)
            best = np.where(better, sdk, best)
            grad = np.where(better[:, None], np.stack([dx[rows, k] / rk, dy[rows, k] / rk], axis=1), grad)
        return best, grad

    def match(self, pts: np.ndarray, prior: tuple[float, float, float], cfg: ScanMatchConfig | None = None,
              laser_xy: tuple[float, float] = (0.0, 0.0), sigma: np.ndarray | None = None) -> ScanFix:
        """Fit the returns ``pts`` (N x 2, base_link at one time) to the map from ``prior`` (base_link in map);
        ``laser_xy``: where the LIDAR sits in base_link; ``sigma``: each return's error (m; default
        ``cfg.sigma_m``)."""
        cfg = cfg or ScanMatchConfig()
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        n = len(pts)
        sig = np.full(n, cfg.sigma_m) if sigma is None else np.maximum(np.asarray(sigma, dtype=float), 1e-6)
        hub = np.maximum(cfg.huber_m, sig)
        gate1 = np.maximum(cfg.outlier_m, 3 * sig)
        if n < cfg.min_points:
            return ScanFix(False, reason="too_few_returns", points=n)
        x = np.array(prior, dtype=float)
        qx, qy = pts[:, 0], pts[:, 1]
        it = 0
        for it in range(1, cfg.max_iterations + 1):
            c, s = math.cos(x[2]), math.sin(x[2])
            w = np.stack([x[0] + c * qx - s * qy, x[1] + s * qx + c * qy], axis=1)
            d, g = self.distance(w, _laser_in_map(x, laser_xy))
            gate = gate1 * (3.0 if it <= 2 else 1.0)  # wider while the prior may be a few cm off
            a = np.abs(d)
            keep = a <= gate
            wts = np.where(a <= hub, 1.0, hub / np.maximum(a, 1e-12)) * keep / sig ** 2
            if np.count_nonzero(keep) < cfg.min_points:
                return ScanFix(False, reason="too_few_on_map", points=n, inliers=int(np.count_nonzero(keep)),
                               iterations=it)
            J = np.stack([g[:, 0], g[:, 1], g[:, 0] * (-s * qx - c * qy) + g[:, 1] * (c * qx - s * qy)], axis=1)
            H = (J * wts[:, None]).T @ J
            b = (J * wts[:, None]).T @ d
            lam = 1e-6 * max(float(np.trace(H)), 1e-12)  # keeps an unconstrained direction at the prior
            try:
                step = -np.linalg.solve(H + lam * np.eye(3), b)
            except np.linalg.LinAlgError:
                return ScanFix(False, reason="numerical", points=n, iterations=it)
            x = x + step
            if abs(step[0]) < 1e-5 and abs(step[1]) < 1e-5 and abs(step[2]) < 1e-5:
                break
        x[2] = wrap_angle(float(x[2]))
        c, s = math.cos(x[2]), math.sin(x[2])
        w = np.stack([x[0] + c * qx - s * qy, x[1] + s * qx + c * qy], axis=1)
        d, g = self.distance(w, _laser_in_map(x, laser_xy))
        inl = np.abs(d) <= gate1
        k = int(np.count_nonzero(inl))
        rms = float(math.sqrt(np.mean(d[inl] ** 2))) if k else math.nan
        chi = float(math.sqrt(np.mean((d[inl] / sig[inl]) ** 2))) if k else math.nan
        fix = ScanFix(False, points=n, inliers=k, rms_m=rms, iterations=it)
        if k < cfg.min_points:
            fix.reason = "too_few_on_map"
            return fix
        if k < cfg.min_inlier_share * n:  # parts, another robot: more of the sweep is off the map than on it
            fix.reason = "mostly_off_map"
            return fix
        if not chi <= cfg.max_rms_sigmas:
            fix.reason = "poor_fit"
            return fix
        if (math.hypot(x[0] - prior[0], x[1] - prior[1]) > cfg.max_correction_m
                or abs(wrap_angle(x[2] - prior[2])) > math.radians(cfg.max_correction_deg)):
            fix.reason = "far_from_prior"
            return fix
        J = np.stack([g[inl, 0], g[inl, 1], g[inl, 0] * (-s * qx[inl] - c * qy[inl])
                      + g[inl, 1] * (c * qx[inl] - s * qy[inl])], axis=1)
        H = (J / sig[inl, None] ** 2).T @ J
        evals, evecs = np.linalg.eigh(0.5 * (H + H.T))
        scale = max(1.0, chi ** 2) * cfg.rays_per_independent
        # an unconstrained direction gets a variance of 1 (m or rad squared): the filter ignores it there
        cov = (evecs * (scale / np.maximum(evals, scale))) @ evecs.T
        if not np.all(np.isfinite(cov)):
            fix.reason = "numerical"
            return fix
        fix.ok, fix.pose, fix.cov = True, (float(x[0]), float(x[1]), float(x[2])), 0.5 * (cov + cov.T)
        return fix


class OdomHistory:
    """The last ``keep_s`` seconds of odometry poses (``odom`` frame), interpolated at any time between them."""

    def __init__(self, keep_s: float = 2.0):
        self.keep_s = keep_s
        self._t: deque[float] = deque()
        self._p: deque[tuple[float, float, float]] = deque()

    def clear(self) -> None:
        self._t.clear()
        self._p.clear()

    def add(self, t: float, pose: tuple[float, float, float]) -> None:
        if self._t and t <= self._t[-1]:
            return
        self._t.append(t)
        self._p.append(tuple(pose))
        while self._t and self._t[0] < t - self.keep_s:
            self._t.popleft()
            self._p.popleft()

    @property
    def latest(self) -> tuple[float, tuple[float, float, float]] | None:
        return (self._t[-1], self._p[-1]) if self._t else None

    def at(self, times: np.ndarray) -> np.ndarray | None:
        """Poses (N x 3) at ``times`` (clamped to the history's ends); None if empty or ``times`` begin more
        than 0.1 s before the history."""
        if not self._t:
            return None
        ts = np.fromiter(self._t, float)
        times = np.asarray(times, dtype=float)
        if times.min() < ts[0] - 0.1:
            return None
        p = np.array(self._p)
        th = np.unwrap(p[:, 2])
        return np.stack([np.interp(times, ts, p[:, 0]), np.interp(times, ts, p[:, 1]),
                         np.interp(times, ts, th)], axis=1)


def deskew(pts_laser: np.ndarray, odom_at_rays: np.ndarray, odom_at_ref: tuple[float, float, float],
           laser_pose: tuple[float, float, float]) -> np.ndarray:
    """Each return (laser frame, measured when odometry was ``odom_at_rays[i]``) in base_link at the
    reference time (odometry ``odom_at_ref``)."""
    lx, ly, lth = laser_pose
    cl, sl = math.cos(lth), math.sin(lth)
    bx = lx + cl * pts_laser[:, 0] - sl * pts_laser[:, 1]
    by = ly + sl * pts_laser[:, 0] + cl * pts_laser[:, 1]
    c, s = np.cos(odom_at_rays[:, 2]), np.sin(odom_at_rays[:, 2])
    ox = odom_at_rays[:, 0] + c * bx - s * by
    oy = odom_at_rays[:, 1] + s * bx + c * by
    rx, ry, rth = odom_at_ref
    cr, sr = math.cos(rth), math.sin(rth)
    dx, dy = ox - rx, oy - ry
    return np.stack([cr * dx + sr * dy, -sr * dx + cr * dy], axis=1)


def body_box(robot, part=None, margin: float = 0.02) -> tuple[float, float, float]:
    """(x_min, x_max, half width) in base_link of what the LIDAR may see of the robot and a held part."""
    x0 = -robot.base["size"][0] / 2
    x1 = robot.electromagnet["x"]
    hw = max(robot.base["size"][1] / 2, robot.track / 2 + robot.wheel.get("width", 0.0) / 2)
    if part is not None:
        x1 += part.depth
        hw = max(hw, part.width / 2)
    return x0 - margin, x1 + margin, hw + margin


class ScanLocalizer:
    """Scans to fixes: the returns in base_link at the sweep's middle (deskewed with odometry), matched from
    the filter's pose carried to that time by odometry. The caller feeds odometry (:meth:`add_odom`) and
    scans (:meth:`add_scan`), and asks for the fix once the odometry covers the scan (:meth:`fix_pending`)."""

    def __init__(self, field, robot, cfg: ScanMatchConfig | None = None):
        self.cfg = cfg or ScanMatchConfig()
        lid = robot.lidar
        self.map = FieldMap(field, lid.xyz[2])
        self.laser_pose = (float(lid.xyz[0]), float(lid.xyz[1]), float(getattr(lid, "yaw", 0.0) or 0.0))
        self.body = body_box(robot, field.part, self.cfg.body_margin_m)
        self.noise = (float(getattr(lid, "noise_a", 0.0) or 0.0), float(getattr(lid, "noise_b", 0.0) or 0.0))
        self.odom = OdomHistory()
        # (ray times, returns in the laser frame, those fitted first, their stride): every usable ray is kept,
        # for a fit with every ray when the strided one has too few on the map
        self._pending: tuple[np.ndarray, np.ndarray, np.ndarray, int] | None = None

    def add_odom(self, t: float, pose: tuple[float, float, float]) -> None:
        self.odom.add(t, pose)

    def reset(self) -> None:
        self.odom.clear()
        self._pending = None

    def sigma(self, pts_laser: np.ndarray) -> np.ndarray:
        """Each return's error: the LIDAR's range noise at its range and ``sigma_m`` (m)."""
        a, b = self.noise
        r = np.hypot(pts_laser[:, 0], pts_laser[:, 1])
        return np.hypot(self.cfg.sigma_m, a * np.exp(b * r))

    def returns(self, ranges: np.ndarray, angles: np.ndarray, range_min: float = 0.0,
                range_max: float = math.inf, stride: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(ray indices, points in the laser frame) of the usable returns: finite, in range, every
        ``stride``-th (default ``cfg.stride``), not on the robot or a held part."""
        ranges = np.asarray(ranges, dtype=float)
        angles = np.asarray(angles, dtype=float)
        idx = np.arange(0, len(ranges), max(1, self.cfg.stride if stride is None else stride))
        r = ranges[idx]
        ok = np.isfinite(r) & (r >= max(range_min, 1e-3)) & (r <= min(range_max, self.cfg.max_range_m))
        idx, r = idx[ok], r[ok]
        a = angles[idx]
        pts = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        lx, ly, lth = self.laser_pose
        bx = lx + math.cos(lth) * pts[:, 0] - math.sin(lth) * pts[:, 1]
        by = ly + math.sin(lth) * pts[:, 0] + math.cos(lth) * pts[:, 1]
        x0, x1, hw = self.body
        keep = ~((bx >= x0) & (bx <= x1) & (np.abs(by) <= hw))
        return idx[keep], pts[keep]

    def add_scan(self, ranges, angles, t0: float, dt: float, range_min: float = 0.0,
                 range_max: float = math.inf) -> ScanFix | None:
        """Take a scan whose ray ``i`` was measured at ``t0 + i * dt``; it is matched (:meth:`fix_pending`)
        once odometry covers its last ray (a scan can arrive before the odometry of the same cycle). A newer
        scan replaces one still waiting. Returns a ScanFix (not ok) when the scan cannot be used at all."""
        idx, pts = self.returns(ranges, angles, range_min, range_max, stride=1)
        stride = max(1, self.cfg.stride)
        first = idx % stride == 0  # what returns(stride=cfg.stride) gives
        if np.count_nonzero(first) < self.cfg.min_points and self.cfg.dense_when_few and stride > 1:
            first[:], stride = True, 1
        if np.count_nonzero(first) < self.cfg.min_points:
            self._pending = None
            return ScanFix(False, reason="too_few_returns", points=int(np.count_nonzero(first)))
        self._pending = (t0 + idx * dt, pts, first, stride)
        return None

    def ready(self) -> bool:
        """A scan waits and odometry reaches its last ray."""
        last = self.odom.latest
        if self._pending is None or last is None:
            return False
        times, _, first, _ = self._pending
        return last[0] >= times[first][-1] - 1e-6

    def fix_pending(self, filter_t: float, filter_pose) -> ScanFix | None:
        """The waiting scan's fix, given the filter's pose ``filter_pose`` at ``filter_t`` (the odometry's
        clock); None while no scan is ready."""
        if not self.ready():
            return None
        times, pts, first, stride = self._pending
        self._pending = None
        if filter_pose is None:
            return ScanFix(False, reason="no_prior")
        f = self._fit(times[first], pts[first], stride, filter_t, filter_pose)
        if f.reason == "too_few_on_map" and self.cfg.dense_when_few_on_map and stride > 1:
            every = times <= times[first][-1]  # the rays odometry covers: up to the last one fitted first
            f = self._fit(times[every], pts[every], 1, filter_t, filter_pose)
        return f

    def _fit(self, times: np.ndarray, pts: np.ndarray, stride: int, filter_t: float, filter_pose) -> ScanFix:
        """The fix from the returns ``pts`` (laser frame, measured at ``times``), every ``stride``-th ray."""
        t_ref = float(0.5 * (times[0] + times[-1]))
        odo = self.odom.at(np.concatenate([times, [t_ref, filter_t]]))
        if odo is None:
            return ScanFix(False, reason="no_odometry", points=len(times))
        ray_odom, ref_odom, filt_odom = odo[:-2], odo[-2], odo[-1]
        body = deskew(pts, ray_odom, tuple(ref_odom), self.laser_pose)
        # the filter's pose carried back (or on) to t_ref by odometry: map<-base(t_ref) = map<-odom * odom<-base
        T = _se2(filter_pose) @ np.linalg.inv(_se2(filt_odom)) @ _se2(ref_odom)
        cfg = self.cfg if stride == self.cfg.stride else replace(  # every ray: neighbours share more errors
            self.cfg, rays_per_independent=self.cfg.rays_per_independent * self.cfg.stride / stride)
        f = self.map.match(body, _pose(T), cfg, self.laser_pose[:2], self.sigma(pts))
        f.t, f.every_ray = t_ref, stride == 1 < self.cfg.stride
        return f
