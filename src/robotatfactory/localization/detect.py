"""ArUco detection: OpenCV's ``ArucoDetector`` with the field's dictionary and sub-pixel corners.

Corners come in OpenCV's order (top-left, top-right, bottom-right, bottom-left of the printed marker) in
pixel coordinates with pixel centres at integers (the convention of ``cx = 319.5`` for a 640-wide image).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np


@dataclass
class DetectorConfig:
    """Settings of the detector. The defaults are tuned on 640x480 frames of the field (``raf bench
    localization`` measures them); sub-pixel refinement matters for accuracy (see docs/localization.md)."""

    dictionary: str = "DICT_5X5_100"
    corner_refinement: str = "subpix"  # none | subpix | contour | apriltag
    adaptive_win_min: int = 5
    adaptive_win_max: int = 15
    adaptive_win_step: int = 10
    adaptive_constant: float = 7.0
    min_perimeter_rate: float = 0.02  # of the image's larger side; 0.02 * 640 = 12.8 px: 3.2 px sides
    polygonal_approx_rate: float = 0.05
    subpix_win: int = 3
    subpix_iterations: int = 30
    subpix_min_accuracy: float = 0.01
    error_correction_rate: float = 0.6
    aruco3: bool = False
    aruco3_min_side_px: int = 32
    extra: dict = field(default_factory=dict)  # any other cv2.aruco.DetectorParameters attribute

    @classmethod
    def from_dict(cls, d: dict | None) -> "DetectorConfig":
        d = dict(d or {})
        known = {k: d.pop(k) for k in list(d) if k in cls.__dataclass_fields__ and k != "extra"}
        extra = dict(d.pop("extra", {}) or {})
        extra.update(d)
        return cls(**known, extra=extra)


APRILTAG_OFFSET_PX = 0.5  # see MarkerDetector.detect

_REFINE = {"none": "CORNER_REFINE_NONE", "subpix": "CORNER_REFINE_SUBPIX",
           "contour": "CORNER_REFINE_CONTOUR", "apriltag": "CORNER_REFINE_APRILTAG"}


def aruco_dictionary(name: str):
    """``cv2.aruco`` predefined dictionary by name (``DICT_5X5_100``)."""
    code = getattr(cv2.aruco, name, None)
    if code is None or not name.startswith("DICT_"):
        from ..errors import ConfigError

        raise ConfigError(f"unknown ArUco dictionary {name!r} (e.g. DICT_5X5_100)")
    return cv2.aruco.getPredefinedDictionary(code)


def detector_parameters(cfg: DetectorConfig) -> "cv2.aruco.DetectorParameters":
    from ..errors import ConfigError

    p = cv2.aruco.DetectorParameters()
    if cfg.corner_refinement not in _REFINE:
        raise ConfigError(f"corner_refinement must be one of {sorted(_REFINE)}, not {cfg.corner_refinement!r}")
    p.cornerRefinementMethod = getattr(cv2.aruco, _REFINE[cfg.corner_refinement])
    p.adaptiveThreshWinSizeMin = int(cfg.adaptive_win_min)
    p.adaptiveThreshWinSizeMax = int(cfg.adaptive_win_max)
    p.adaptiveThreshWinSizeStep = int(cfg.adaptive_win_step)
    p.adaptiveThreshConstant = float(cfg.adaptive_constant)
    p.minMarkerPerimeterRate = float(cfg.min_perimeter_rate)
    p.polygonalApproxAccuracyRate = float(cfg.polygonal_approx_rate)
    p.cornerRefinementWinSize = int(cfg.subpix_win)
    p.cornerRefinementMaxIterations = int(cfg.subpix_iterations)
    p.cornerRefinementMinAccuracy = float(cfg.subpix_min_accuracy)
    p.errorCorrectionRate = float(cfg.error_correction_rate)
    p.useAruco3Detection = bool(cfg.aruco3)
    p.minSideLengthCanonicalImg = int(cfg.aruco3_min_side_px)
    for k, v in cfg.extra.items():
        if not hasattr(p, k):
            raise ConfigError(f"detector setting {k!r} is not a cv2.aruco.DetectorParameters attribute")
        setattr(p, k, v)
    return p


@dataclass(frozen=True)
class Detection:
    """One detected marker: its ID and 4x2 corners (pixels, OpenCV order)."""

    id: int
    corners: np.ndarray  # 4x2 float64

    @property
    def center(self) -> np.ndarray:
        return self.corners.mean(axis=0)

    def perimeter(self) -> float:
        return float(np.sum(np.linalg.norm(np.roll(self.corners, -1, axis=0) - self.corners, axis=1)))

    def area(self) -> float:
        """Signed area (pixels^2); positive for OpenCV's clockwise-on-screen corner order."""
        x, y = self.corners[:, 0], self.corners[:, 1]
        return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


class MarkerDetector:
    """Detects markers in a BGR or grey image. Not thread-safe (one per thread)."""

    def __init__(self, cfg: DetectorConfig | None = None):
        self.cfg = cfg or DetectorConfig()
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(self.cfg.dictionary),
                                                 detector_parameters(self.cfg))

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Markers in the image, sorted by ID. ``image``: HxW grey or HxWx3 BGR uint8."""
        if image is None or image.ndim not in (2, 3) or image.size == 0:
            return []
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        corners, ids, _ = self._detector.detectMarkers(grey)
        if ids is None:
            return []
        # OpenCV's AprilTag refinement (a port of AprilTag's quad fit) puts pixel centres at +0.5, not at
        # integers like the rest of OpenCV (AprilRobotics/apriltag issue 121); measured on the stand-in's and
        # the synthetic frames: corners +0.43..+0.45 px in u and v. Back to OpenCV's convention:
        shift = APRILTAG_OFFSET_PX if self.cfg.corner_refinement == "apriltag" else 0.0
        out = [Detection(int(i), np.asarray(c, dtype=np.float64).reshape(4, 2) - shift)
               for i, c in zip(ids.ravel(), corners)]
        return sorted(out, key=lambda d: d.id)


def undistort_detections(dets: list[Detection], K: np.ndarray, D: np.ndarray | None) -> list[Detection]:
    """The detections with their corners moved to where an ideal pinhole camera with matrix ``K`` would see
    them (OpenCV's ``undistortPoints`` with ``P = K``), for a camera with distortion ``D`` (k1, k2, p1, p2,
    k3). With no distortion (``D`` None or all zeros) the same list is returned."""
    if D is None or not np.any(np.asarray(D, dtype=np.float64)) or not dets:
        return dets
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    D = np.asarray(D, dtype=np.float64).ravel()
    pts = np.concatenate([np.asarray(d.corners, dtype=np.float64).reshape(4, 2) for d in dets]).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    und = cv2.undistortPointsIter(pts, K, D, None, K, crit).reshape(-1, 4, 2)
    return [Detection(d.id, c.astype(np.float64)) for d, c in zip(dets, und)]

