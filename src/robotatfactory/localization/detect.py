"""ArUco detection: OpenCV's ``ArucoDetector`` with the field's dictionary and sub-pixel corners.

Corners come in OpenCV's order (top-left, top-right, bottom-right, bottom-left of the printed marker) in
pixel coordinates with pixel centres at integers (the convention of ``cx = 319.5`` for a 640-wide image).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..settings import setting

#: corner_refinement's choices: OpenCV's names
REFINEMENTS = {"none": "CORNER_REFINE_NONE", "subpix": "CORNER_REFINE_SUBPIX",
               "contour": "CORNER_REFINE_CONTOUR", "apriltag": "CORNER_REFINE_APRILTAG"}


def _mapping_setting(doc: str):
    """A setting holding a free-form mapping (default empty): :func:`..settings.build` takes it as it is, the
    class's ``check()`` judges it."""
    return field(default_factory=dict, metadata=setting(None, doc, kind=dict).metadata)


@dataclass(frozen=True)
class DetectorConfig:
    """Settings of the detector (``detector.*``). The defaults are tuned on 640x480 frames of the field (``raf
    bench localization`` measures them); sub-pixel refinement matters for accuracy (see docs/localization.md).
    The ranges are what OpenCV's ``ArucoDetector`` accepts (it asserts them)."""

    corner_refinement: str = setting("subpix", "cv2.aruco corner refinement: none | subpix | contour | apriltag; "
                                               "sub-pixel corners matter for accuracy", choices=tuple(REFINEMENTS))
    adaptive_win_min: int = setting(5, "px, the smallest adaptive-threshold window (windows 5, 15 px: measured "
                                       "with `raf bench localization --sweep`)", lo=3)
    adaptive_win_max: int = setting(15, "px, the largest adaptive-threshold window (at least adaptive_win_min)",
                                    lo=3)
    adaptive_win_step: int = setting(10, "px between the adaptive-threshold windows", lo=1)
    adaptive_constant: float = setting(7.0, "grey levels subtracted from the local mean in the adaptive "
                                            "threshold")
    min_perimeter_rate: float = setting(0.02, "the smallest marker perimeter, as a fraction of the image's larger "
                                              "side (0.02 x 640 = 12.8 px: 3.2 px sides)", lo=0.0, hi=4.0,
                                        lo_open=True)
    polygonal_approx_rate: float = setting(0.05, "polygon fit tolerance, as a fraction of the contour's "
                                                 "perimeter", lo=0.0, hi=1.0, lo_open=True)
    subpix_win: int = setting(3, "px, half window of the sub-pixel corner refinement", lo=1)
    subpix_iterations: int = setting(30, "most iterations of the sub-pixel refinement", lo=1)
    subpix_min_accuracy: float = setting(0.01, "px: the sub-pixel refinement stops below this change", lo=0.0,
                                         lo_open=True)
    error_correction_rate: float = setting(0.6, "share of the dictionary's bit-error correction used", lo=0.0,
                                           hi=1.0)
    aruco3: bool = setting(False, "OpenCV's ArUco3 speed-up (misses small markers)")
    aruco3_min_side_px: int = setting(32, "px, the side of the canonical image ArUco3 scales markers to", lo=1)
    extra: dict = _mapping_setting("any other cv2.aruco.DetectorParameters attribute by its OpenCV name "
                                   "(minDistanceToBorder: 2), set as it is; --set detector.extra.NAME=VALUE")
    # set in code, not a setting: the field's own (FrameLocalizer takes it from the field file)
    dictionary: str = "DICT_5X5_100"

    def check(self) -> None:
        """The rules across settings, and ``extra``'s names and values as OpenCV takes them."""
        from ..errors import ConfigError

        if self.adaptive_win_max < self.adaptive_win_min:
            raise ConfigError(f"setting detector.adaptive_win_max must be at least detector.adaptive_win_min "
                              f"({self.adaptive_win_min}), got {self.adaptive_win_max}")
        if not isinstance(self.extra, Mapping):
            raise ConfigError(f"setting detector.extra must be a mapping of cv2.aruco.DetectorParameters names to "
                              f"values, got {self.extra!r}")
        object.__setattr__(self, "extra", dict(self.extra))  # a copy: the caller's mapping stays theirs
        detector_parameters(self)


APRILTAG_OFFSET_PX = 0.5  # see MarkerDetector.detect


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
    p.cornerRefinementMethod = getattr(cv2.aruco, REFINEMENTS[cfg.corner_refinement])
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
        if not isinstance(k, str) or k.startswith("_") or not hasattr(p, k) or callable(getattr(p, k)):
            raise ConfigError(f"setting detector.extra.{k}: not a cv2.aruco.DetectorParameters attribute (e.g. "
                              f"minDistanceToBorder)")
        try:
            setattr(p, k, v)
        except (TypeError, ValueError, cv2.error) as e:
            raise ConfigError(f"setting detector.extra.{k} must be of OpenCV's type for it "
                              f"({type(getattr(p, k)).__name__}), got {v!r}: {e}") from None
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

