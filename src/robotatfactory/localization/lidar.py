"""LIDAR beacons: find the 0.09 m cylinders (the field's ``beacons``) in a 2D scan and measure their centres.

A scan is N ranges at known angles in the ``laser`` frame (SimTwo's ranger2d: -1 or anything above
range_max means no return; REP 117 as the bridge publishes it: +Inf no return, NaN invalid, e.g. a ray that
ended on the robot's own wheel, -Inf or below range_min too close). A cluster next to a NaN or too-close
ray is not trusted: its edge may be hidden. Consecutive returns closer to each other than a jump threshold form
a cluster; a cluster no wider than a beacon, standing in front of what is around it, is fitted with a circle
of the known radius (Gauss-Newton); its centre's range and bearing, with a covariance from the fit (the
range noise of the LIDAR model), are the measurement. Association with a known beacon is the EKF's job
(:meth:`robotatfactory.localization.ekf.Ekf.beacons`, Mahalanobis-gated).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..settings import setting


@dataclass(frozen=True)
class BeaconConfig:
    """Settings of the beacon extraction (``beacons.*``)."""

    diameter_m: float = setting(0.09, "m, the beacon cylinders' diameter", lo=0.0, lo_open=True)
    min_points: int = setting(3, "fewest LIDAR returns on a beacon", lo=2)
    width_tolerance_m: float = setting(0.03, "m a cluster may be wider than the diameter (noise)", lo=0.0)
    jump_m: float = setting(0.05, "m: neighbouring returns farther apart than this (plus 3 ray spacings) start a "
                                  "new cluster", lo=0.0)
    foreground_m: float = setting(0.05, "m: the returns next to a cluster must be this much farther (or none)",
                                  lo=0.0)
    max_range_m: float = setting(3.0, "m: beacons farther away are ignored", lo=0.0, lo_open=True)
    max_fit_rms_m: float = setting(0.015, "m: a circle fit with a larger RMS residual (and above 3 sigma) is not "
                                          "a beacon", lo=0.0)
    noise_a: float = setting(0.001524, "m, the LIDAR's range noise sigma = noise_a x exp(noise_b x range)", lo=0.0)
    noise_b: float = setting(1.3103, "1/m, likewise")
    min_sigma_m: float = setting(0.002, "m, the per-return sigma at least (model error, beam width)", lo=0.0,
                                 lo_open=True)


@dataclass(frozen=True)
class BeaconObservation:
    range_m: float  # laser origin to the cylinder's centre
    bearing_rad: float  # in the laser frame, counter-clockwise from its x axis
    var_range: float
    var_bearing: float
    n_points: int
    fit_rms_m: float
    center: tuple[float, float]  # in the laser frame
    index: float = 0.0  # mean ray index of the cluster (its time within a sweep)

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (self.range_m, self.bearing_rad, self.var_range, self.var_bearing)


def _clusters(valid: np.ndarray, pts: np.ndarray, rng: np.ndarray, step: float, jump: float,
              circular: bool) -> list[np.ndarray]:
    n = len(valid)
    out, cur = [], []
    for i in range(n):
        if not valid[i]:
            if cur:
                out.append(cur)
                cur = []
            continue
        if cur:
            j = cur[-1]
            thr = jump + 3 * step * max(rng[i], rng[j])
            if np.linalg.norm(pts[i] - pts[j]) > thr:
                out.append(cur)
                cur = []
        cur.append(i)
    if cur:
        out.append(cur)
    if circular and len(out) > 1 and out[0][0] == 0 and out[-1][-1] == n - 1:
        i, j = out[-1][-1], out[0][0]
        thr = jump + 3 * step * max(rng[i], rng[j])
        if np.linalg.norm(pts[i] - pts[j]) <= thr:
            out[0] = out[-1] + out[0]
            out.pop()
    return [np.array(c) for c in out]


def fit_circle(pts: np.ndarray, radius: float, sigma: float) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Centre (2,), its covariance (2x2) and the RMS residual of a circle of known radius through points
    seen from the origin (the centre is behind the points)."""
    m = pts.mean(axis=0)
    nm = np.linalg.norm(m)
    if nm < 1e-6:
        return None
    c = m + radius * m / nm * 0.8
    for _ in range(10):
        d = pts - c
        dist = np.linalg.norm(d, axis=1)
        if np.any(dist < 1e-9):
            return None
        r = dist - radius
        J = -d / dist[:, None]
        try:
            step = np.linalg.lstsq(J, -r, rcond=None)[0]
        except np.linalg.LinAlgError:
            return None
        c = c + step
        if np.linalg.norm(step) < 1e-7:
            break
    d = pts - c
    dist = np.linalg.norm(d, axis=1)
    r = dist - radius
    J = -d / dist[:, None]
    A = J.T @ J
    if np.linalg.cond(A) > 1e8 or np.linalg.norm(c) < np.linalg.norm(m):
        return None
    cov = np.linalg.inv(A) * sigma ** 2
    return c, cov, float(np.sqrt(np.mean(r ** 2)))


def _line_rms(pts: np.ndarray) -> float:
    """RMS distance of points to their best-fitting line."""
    d = pts - pts.mean(axis=0)
    return float(np.sqrt(np.linalg.eigvalsh(d.T @ d)[0] / len(pts)))


def extract_beacons(ranges: np.ndarray, angles: np.ndarray, cfg: BeaconConfig | None = None,
                    range_min: float = 0.02, range_max: float = 6.0) -> list[BeaconObservation]:
    """Beacon candidates in one scan (laser frame)."""
    cfg = cfg or BeaconConfig()
    rng = np.asarray(ranges, dtype=float).ravel()
    ang = np.asarray(angles, dtype=float).ravel()
    if len(rng) != len(ang) or len(rng) < 3:
        return []
    # a full turn repeats one angle (SimTwo's ranger2d): drop the duplicate last ray
    circular = abs(((ang[-1] - ang[0]) % (2 * math.pi))) < 1e-6 or \
        abs(((ang[-1] - ang[0]) % (2 * math.pi)) - 2 * math.pi) < 1e-6
    if circular:
        rng, ang = rng[:-1], ang[:-1]
    step = float(np.median(np.abs(np.diff(ang)))) if len(ang) > 1 else 0.0
    circular = circular or abs(len(ang) * step - 2 * math.pi) < 1.5 * step
    valid = np.isfinite(rng) & (rng >= range_min) & (rng <= min(range_max, cfg.max_range_m))
    r0 = np.where(valid, rng, 0.0)
    pts = np.stack([r0 * np.cos(ang), r0 * np.sin(ang)], axis=1)
    out = []
    n = len(rng)
    radius = cfg.diameter_m / 2
    for idx in _clusters(valid, pts, r0, step, cfg.jump_m, circular):
        if len(idx) < cfg.min_points:
            continue
        p = pts[idx]
        if np.linalg.norm(p[-1] - p[0]) > cfg.diameter_m + cfg.width_tolerance_m:
            continue
        near = float(r0[idx].min())
        fg = True
        for k in (idx[0] - 1, idx[-1] + 1):
            if not circular and (k < 0 or k >= n):
                continue
            k %= n
            if valid[k] and rng[k] < near + cfg.foreground_m:
                fg = False
            elif not valid[k] and (np.isnan(rng[k]) or 0 <= rng[k] < range_min or rng[k] == -np.inf):
                # unknown (NaN: a ray the bridge filtered as a hit on the robot itself, or not received) or
                # too close (below range_min, -Inf): it may hide the cluster's edge
                fg = False
        if not fg:
            continue
        sigma = max(cfg.min_sigma_m, cfg.noise_a * math.exp(cfg.noise_b * near))
        fit = fit_circle(p, radius, sigma)
        if fit is None:
            continue
        c, cov, rms = fit
        if rms > max(cfg.max_fit_rms_m, 3 * sigma):
            continue
        half = min(radius, float(np.linalg.norm(p[-1] - p[0])) / 2)
        sagitta = radius - math.sqrt(radius ** 2 - half ** 2)
        if sagitta > 2 * sigma and _line_rms(p) < rms:
            continue  # a flat face (a wall, a box side) that fits a line better than the cylinder
        rho = float(np.hypot(c[0], c[1]))
        u = c / rho
        # polar covariance: range along u, bearing across u / rho
        var_r = float(u @ cov @ u)
        v = np.array([-u[1], u[0]])
        var_b = float(v @ cov @ v) / rho ** 2 + (step / math.sqrt(12)) ** 2 / len(idx)
        # mean ray index, unwrapped across the end of a full turn
        ii = np.asarray(idx, dtype=float)
        if circular and ii.max() - ii.min() > n / 2:
            ii = np.where(ii < n / 2, ii + n, ii)
        mid = float(np.mean(ii)) % n
        out.append(BeaconObservation(rho, math.atan2(c[1], c[0]), max(var_r, 1e-8), max(var_b, 1e-10),
                                     len(idx), rms, (float(c[0]), float(c[1])), mid))
    return out


def simulate_scan(pose: tuple[float, float, float], beacons, diameter: float, angles: np.ndarray,
                  laser_xy=(0.0, 0.0), noise: tuple[float, float] = (0.001524, 1.3103),
                  range_max: float = 6.0, rng: np.random.Generator | None = None,
                  segments: list[tuple[tuple[float, float], tuple[float, float]]] = ()) -> np.ndarray:
    """Ranges of a 2D LIDAR at pose seeing cylinders (and optional wall segments); -1 for no return.
    For tests and examples."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    ox = pose[0] + c * laser_xy[0] - s * laser_xy[1]
    oy = pose[1] + s * laser_xy[0] + c * laser_xy[1]
    out = np.full(len(angles), np.inf)
    R = diameter / 2
    for i, a in enumerate(angles):
        dx, dy = math.cos(pose[2] + a), math.sin(pose[2] + a)
        best = np.inf
        for bx, by in beacons:
            fx, fy = ox - bx, oy - by
            b = fx * dx + fy * dy
            cc = fx * fx + fy * fy - R * R
            disc = b * b - cc
            if disc >= 0:
                t = -b - math.sqrt(disc)
                if t > 0:
                    best = min(best, t)
        for (x1, y1), (x2, y2) in segments:
            ex, ey = x2 - x1, y2 - y1
            den = dx * ey - dy * ex
            if abs(den) < 1e-12:
                continue
            t = ((x1 - ox) * ey - (y1 - oy) * ex) / den
            u = ((x1 - ox) * dy - (y1 - oy) * dx) / den
            if t > 0 and 0 <= u <= 1:
                best = min(best, t)
        out[i] = best
    if rng is not None:
        fin = np.isfinite(out)
        out[fin] += rng.normal(0, noise[0] * np.exp(noise[1] * out[fin]))
    out[~np.isfinite(out) | (out > range_max)] = -1.0
    return out
