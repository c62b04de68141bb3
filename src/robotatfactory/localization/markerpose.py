"""Per-marker poses (IPPE, both solutions), the camera-mount check and the corner noise model.

Frames: ``T_cam_marker`` maps marker-frame points into ``camera_optical`` (x right, y down, z forward);
``T_world_cam = T_world_marker @ inv(T_cam_marker)`` (the paper's equation 1); the robot's ``base_link`` is
``T_world_base = T_world_cam @ inv(T_base_cam)`` with the camera mount ``T_base_cam`` from the robot file.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..field.model import Field, Marker
from ..settings import setting
from . import reasons
from .detect import Detection
from .geometry import inv, rt_matrix, tilt_angle


@dataclass(frozen=True)
class PoseConfig:
    """Settings of the pose estimators (``pose.*``; units in the names, angles in degrees).

    Corner noise, pixels (1 sigma per coordinate): ``sigma = min(sigma_max_px, sigma_min_px + sigma_px_per_m * d
    / max(cos a, 0.1) ** sigma_cos_exp)``, d the camera-to-marker distance (m), a the angle between the marker's
    normal and the line of sight; fitted (maximum likelihood) to the corner errors of 150 stand-in simulator
    frames (docs/localization.md)."""

    # the corner noise model
    sigma_min_px: float = setting(0.28, "px, the corner noise of a near marker seen square on (fitted to the "
                                        "corner errors of stand-in simulator frames)", lo=0.0, lo_open=True)
    sigma_px_per_m: float = setting(0.16, "px/m, growth of the corner noise with distance", lo=0.0)
    sigma_cos_exp: float = setting(2.0, "growth of the corner noise with the viewing angle (exponent of 1/cos)",
                                   lo=0.0)
    sigma_max_px: float = setting(1.4, "px, the corner noise at most (0: no cap)", lo=0.0)
    # mount check: base_link implied by a camera pose must be on the floor and level
    mount_max_height_m: float = setting(0.04, "m: a camera pose must put base_link this close to the floor ...",
                                        lo=0.0)
    mount_max_tilt_deg: float = setting(8.0, "deg: ... and this close to level (camera tilt and roll as mounted)",
                                        lo=0.0, hi=180.0)
    mount_sigma_height_m: float = setting(0.01, "m, the height error that counts as 1 sigma when IPPE's two "
                                                "solutions are ranked by the mount check", lo=0.0, lo_open=True)
    mount_sigma_tilt_deg: float = setting(2.0, "deg, likewise for the tilt", lo=0.0, hi=180.0, lo_open=True)
    # per-marker sanity
    marker_max_rms_px: float = setting(1.0, "px: a marker whose corners IPPE's square fits worse than max(this, "
                                            "marker_rms_sigmas x sigma) is rejected (a corner is off: occlusion, "
                                            "a neighbour)", lo=0.0)
    marker_rms_sigmas: float = setting(5.0, "corner sigmas, the other half of that limit", lo=0.0)
    min_side_px: float = setting(4.0, "px: a marker with a shorter side is rejected", lo=0.0)
    min_area_px2: float = setting(20.0, "px^2: a marker with a smaller area is rejected", lo=0.0)
    max_side_ratio: float = setting(12.0, "a marker whose longest side is more than this many times its shortest "
                                          "is rejected", lo=1.0)
    max_marker_distance_m: float = setting(2.5, "m: a marker farther from the camera is rejected", lo=0.0,
                                           lo_open=True)
    # frame-level
    lone_marker_max_distance_m: float = setting(0.45, "m: a fix from one marker only that is farther than this is "
                                                      "rejected (IPPE's ambiguity zone)", lo=0.0)
    marker_outlier_chi2: float = setting(60.0, "chi-square of one marker's 8 corner residuals (normalised by the "
                                               "noise model) above which the fit drops it as an outlier",
                                         lo=0.0, lo_open=True)
    max_rms_px: float = setting(3.0, "px: a fix whose reprojection RMS is larger is rejected", lo=0.0,
                                lo_open=True)
    field_margin_m: float = setting(0.15, "m: a fix farther than this outside the field is rejected", lo=0.0)
    max_position_sigma_m: float = setting(0.10, "m: a fix less certain than this (position sigma) is rejected",
                                          lo=0.0, lo_open=True)
    max_heading_sigma_deg: float = setting(10.0, "deg: ... or than this in heading", lo=0.0, hi=180.0,
                                           lo_open=True)
    # covariance
    floor_position_sigma_m: float = setting(0.0005, "m, the model-error floor added to each planar fix's "
                                                    "covariance (camera model, mount, timing within a frame)",
                                            lo=0.0)
    floor_heading_sigma_deg: float = setting(0.1, "deg, the same floor for the heading", lo=0.0)
    consensus_px: float = setting(10.0, "px: a marker agrees with a hypothesis when its RMS reprojection error is "
                                        "under this", lo=0.0, lo_open=True)
    refine_seeds: int = setting(2, "the best-supported hypotheses that seed the planar fit's least squares", lo=1)
    seed_markers: int = setting(2, "the closest markers whose mount-checked IPPE solutions seed the all-marker "
                                   "PnP", lo=1)

    def corner_sigma(self, distance: float, cos_view: float) -> float:
        s = self.sigma_min_px + self.sigma_px_per_m * distance / max(cos_view, 0.1) ** self.sigma_cos_exp
        return min(self.sigma_max_px, s) if self.sigma_max_px > 0 else s


@dataclass
class MountCheck:
    height_m: float  # base_link's z implied by the camera pose (0 on the floor)
    tilt_rad: float  # angle between base_link's z and the world's z (camera tilt or roll error)
    ok: bool
    score: float  # (height/sigma)^2 + (tilt/sigma)^2, smaller is better


def mount_check(T_world_cam: np.ndarray, T_cam_base: np.ndarray, cfg: PoseConfig) -> MountCheck:
    """Is a camera pose consistent with the camera on a robot standing on the floor?"""
    T_wb = T_world_cam @ T_cam_base
    h = float(T_wb[2, 3])
    tilt = tilt_angle(T_wb[:3, :3])
    ok = abs(h) <= cfg.mount_max_height_m and tilt <= math.radians(cfg.mount_max_tilt_deg)
    score = (h / cfg.mount_sigma_height_m) ** 2 + (tilt / math.radians(cfg.mount_sigma_tilt_deg)) ** 2
    return MountCheck(h, tilt, ok, score)


@dataclass
class MarkerObservation:
    """A detected field marker with its IPPE poses. ``solutions[0]`` is IPPE's best (lowest error)."""

    marker: Marker
    corners: np.ndarray  # 4x2 pixels
    solutions: list[np.ndarray]  # T_cam_marker candidates (4x4)
    errors_px: list[float]  # RMS reprojection error of each solution
    mount: list[MountCheck]  # mount check of each solution
    distance_m: float  # camera to marker centre (best solution)
    cos_view: float  # cos of the angle between the marker's normal and the line of sight
    sigma_px: float  # corner noise (1 sigma per coordinate) from the model
    checked: int | None = None  # index of the solution the mount check picks (None: none passes)

    @property
    def id(self) -> int:
        return self.marker.id

    def T_world_cam(self, i: int = 0) -> np.ndarray:
        return self.marker.pose @ inv(self.solutions[i])


def _degenerate(c: np.ndarray, cfg: PoseConfig) -> bool:
    if not np.all(np.isfinite(c)):
        return True
    nxt = [1, 2, 3, 0]
    e = c[nxt] - c
    sides = np.sqrt(e[:, 0] ** 2 + e[:, 1] ** 2)
    if sides.min() < cfg.min_side_px or sides.max() > cfg.max_side_ratio * sides.min():
        return True
    e2 = e[nxt]
    cross = e[:, 0] * e2[:, 1] - e[:, 1] * e2[:, 0]
    if not ((cross > 0).all() or (cross < 0).all()):  # not strictly convex
        return True
    x, y = c[:, 0], c[:, 1]
    area = 0.5 * abs(float(x @ y[nxt] - y @ x[nxt]))
    return area < cfg.min_area_px2


def observe(detections: list[Detection], field: Field, K: np.ndarray, T_cam_base: np.ndarray,
            cfg: PoseConfig, rejected: list[tuple[int, str]] | None = None) -> list[MarkerObservation]:
    """Per-marker IPPE for every usable detection; unusable ones go to ``rejected`` as (id, reason)."""
    rejected = rejected if rejected is not None else []
    ids = [d.id for d in detections]
    out = []
    for d in detections:
        if not field.has_marker(d.id):
            rejected.append((d.id, reasons.UNKNOWN_ID))
            continue
        if ids.count(d.id) > 1:
            rejected.append((d.id, reasons.DUPLICATE_ID))
            continue
        c = np.asarray(d.corners, dtype=np.float64).reshape(4, 2)
        if _degenerate(c, cfg):
            rejected.append((d.id, reasons.DEGENERATE))
            continue
        m = field.marker(d.id)
        try:
            n, rvecs, tvecs, errs = cv2.solvePnPGeneric(m.corners_local, c, K, None,
                                                        flags=cv2.SOLVEPNP_IPPE_SQUARE)
        except cv2.error:
            n = 0
        if not n:
            rejected.append((d.id, reasons.PNP_FAILED))
            continue
        sols = [rt_matrix(r, t) for r, t in zip(rvecs, tvecs)]
        errs = [float(e) for e in np.asarray(errs).ravel()] if errs is not None else [0.0] * len(sols)
        keep = [i for i, T in enumerate(sols) if np.all(np.isfinite(T)) and T[2, 3] > 0]
        if not keep:
            rejected.append((d.id, reasons.PNP_FAILED))
            continue
        sols, errs = [sols[i] for i in keep], [errs[i] for i in keep]
        dist = float(np.linalg.norm(sols[0][:3, 3]))
        if dist > cfg.max_marker_distance_m:
            rejected.append((d.id, reasons.TOO_FAR))
            continue
        T_wc = [m.pose @ inv(T) for T in sols]
        mounts = [mount_check(T, T_cam_base, cfg) for T in T_wc]
        passing = [i for i, mc in enumerate(mounts) if mc.ok]
        checked = min(passing, key=lambda i: mounts[i].score) if passing else None
        cam_pos = T_wc[0][:3, 3]
        los = cam_pos - m.position
        cos_view = abs(float(np.dot(los, m.normal))) / max(float(np.linalg.norm(los)), 1e-9)
        sigma = cfg.corner_sigma(dist, cos_view)
        if min(errs) > max(cfg.marker_max_rms_px, cfg.marker_rms_sigmas * sigma):
            rejected.append((d.id, reasons.REPROJECTION))
            continue
        out.append(MarkerObservation(m, c, sols, errs, mounts, dist, cos_view, sigma, checked))
    return out
