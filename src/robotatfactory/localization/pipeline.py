"""One camera frame in, every pose estimate out: detection, per-marker IPPE, the three methods, counters.

Used by the ROS node (``raf localize``), the bench and the experiment, so all three run the same code.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from ..field.model import Field
from ..robot import RobotSpec
from . import reasons
from .detect import Detection, DetectorConfig, MarkerDetector, undistort_detections
from .estimators import PlanarModel, PoseEstimate, all_markers_pnp, closest_marker, consensus, planar_fit
from .geometry import inv
from .markerpose import MarkerObservation, PoseConfig, observe

METHODS = ("closest", "closest_checked", "all_pnp", "planar")


@dataclass
class FrameResult:
    detections: list[Detection]
    observations: list[MarkerObservation]
    rejected: list[tuple[int, str]]  # (marker id, reason) of detections not used
    estimates: dict[str, PoseEstimate]
    stamp: float | None = None
    detect_ms: float = 0.0
    pose_ms: float = 0.0

    def best(self, method: str = "planar") -> PoseEstimate | None:
        e = self.estimates.get(method)
        return e if e is not None and e.ok else None


class FrameLocalizer:
    """Holds the detector, the camera model and the rejection counters (``counts``: reason -> number)."""

    def __init__(self, field: Field, robot: RobotSpec, detector: DetectorConfig | None = None,
                 pose: PoseConfig | None = None, methods: tuple[str, ...] = METHODS, K: np.ndarray | None = None,
                 D: np.ndarray | None = None):
        bad = sorted(set(methods) - set(METHODS))
        if bad:
            from ..errors import ConfigError

            raise ConfigError(f"unknown localization methods {bad}; choose from {list(METHODS)}")
        self.field, self.robot = field, robot
        dcfg = detector or DetectorConfig()
        if dcfg.dictionary != field.dictionary:
            dcfg = replace(dcfg, dictionary=field.dictionary)
        self.detector = MarkerDetector(dcfg)
        self.cfg = pose or PoseConfig()
        self.methods = tuple(methods)
        self.T_base_cam = robot.camera.base_to_optical()
        self.T_cam_base = inv(self.T_base_cam)
        self.set_intrinsics(robot.camera.K if K is None else K, robot.camera.D if D is None else D)
        self.counts: Counter = Counter()
        self.frames = 0

    def set_intrinsics(self, K: np.ndarray, D: np.ndarray | None = None) -> None:
        """Use another camera matrix and distortion (k1, k2, p1, p2, k3; e.g. from camera_info). Detected
        corners are undistorted to the pinhole camera ``K`` before any pose estimate; ``D`` None keeps the
        present distortion, zeros mean none."""
        from ..errors import ConfigError

        K = np.asarray(K, dtype=np.float64).reshape(3, 3)
        if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ConfigError(f"camera matrix must be finite with positive focal lengths, got {K.tolist()}")
        if D is not None:
            D = np.asarray(D, dtype=np.float64).ravel()
            if D.size > 8 or not np.all(np.isfinite(D)):
                raise ConfigError(f"distortion must be up to 8 finite OpenCV coefficients, got {D.tolist()}")
            D = np.concatenate([D, np.zeros(max(0, 5 - D.size))])
            self.D = D if np.any(D) else None
        elif not hasattr(self, "D"):
            self.D = None
        self.K = K
        self.model = PlanarModel(K, self.T_base_cam)

    def process(self, image: np.ndarray, prior: tuple[float, float, float] | None = None,
                stamp: float | None = None) -> FrameResult:
        t0 = time.perf_counter()
        dets = self.detector.detect(image)
        t1 = time.perf_counter()
        res = self.process_detections(dets, prior, stamp)
        res.detect_ms = (t1 - t0) * 1e3
        return res

    def process_detections(self, dets: list[Detection], prior: tuple[float, float, float] | None = None,
                           stamp: float | None = None) -> FrameResult:
        t0 = time.perf_counter()
        self.frames += 1
        rejected: list[tuple[int, str]] = []
        pin = undistort_detections(dets, self.K, self.D)  # pinhole pixels from here on
        obs = observe(pin, self.field, self.K, self.T_cam_base, self.cfg, rejected)
        for _, r in rejected:
            self.counts[r] += 1
        est: dict[str, PoseEstimate] = {}
        if not obs:
            self.counts[reasons.NO_MARKERS] += 1
        agreed = consensus(obs, self.model, self.T_cam_base, self.cfg, prior) if obs else ([], [])
        for m in self.methods:
            if m == "closest":
                e = closest_marker(obs, self.field, self.K, self.T_cam_base, self.cfg, checked=False)
            elif m == "closest_checked":
                e = closest_marker(obs, self.field, self.K, self.T_cam_base, self.cfg, checked=True)
            elif m == "all_pnp":
                e = all_markers_pnp(agreed[0] or obs, self.field, self.K, self.T_cam_base, self.cfg)
            else:
                e = planar_fit(obs, self.field, self.K, self.T_base_cam, self.cfg, prior=prior, model=self.model,
                               agreed=agreed)
                for mid in e.dropped:
                    rejected.append((mid, reasons.MARKER_OUTLIER))
                    self.counts[reasons.MARKER_OUTLIER] += 1
            est[m] = e
            if obs and not e.ok and e.reason:
                self.counts[f"{m}:{e.reason}"] += 1
        return FrameResult(dets, obs, rejected, est, stamp, 0.0, (time.perf_counter() - t0) * 1e3)
