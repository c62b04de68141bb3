"""Synthetic camera views of the field, for tests and the bench (no simulator needed).

Markers are drawn by warping ``cv2.aruco.generateImageMarker`` images (with a white quiet zone one module
wide) through the homography of their plate into the image, supersampled and area-averaged, onto a uniform
floor; optional Gaussian blur and pixel noise. No occlusion: walls are not drawn. Pixel convention: OpenCV's
(pixel centres at integers), the same as ``cx = 319.5``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..field.model import CORNER_UNITS, Field, Marker
from ..robot import CameraSpec
from .geometry import inv, se2_matrix

MODULES = 7  # 5x5 bits + a one-module black border
QUIET = 1  # white modules around the marker


def camera_world_pose(camera: CameraSpec, pose: tuple[float, float, float]) -> np.ndarray:
    """4x4 world <- camera_optical for the robot at pose (x, y, theta)."""
    return se2_matrix(*pose) @ camera.base_to_optical()


def project(points_world: np.ndarray, T_world_cam: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (Nx2) and depths (N) of world points seen by a pinhole camera without distortion."""
    T = inv(T_world_cam)
    pc = points_world @ T[:3, :3].T + T[:3, 3]
    z = pc[:, 2]
    uv = (pc @ K.T)[:, :2] / np.where(np.abs(z) < 1e-9, 1e-9, z)[:, None]
    return uv, z


@dataclass(frozen=True)
class VisibleMarker:
    id: int
    corners: np.ndarray  # 4x2 true pixel corners, OpenCV order
    distance: float  # camera centre to marker centre, m


def visible_markers(field: Field, camera: CameraSpec, T_world_cam: np.ndarray, margin_px: float = 2.0,
                    min_side_px: float = 0.0, max_distance: float = np.inf) -> list[VisibleMarker]:
    """Markers whose four corners are in front of the camera and inside the image (by ``margin_px``), with
    their printed face towards the camera."""
    K = camera.K
    cam_pos = T_world_cam[:3, 3]
    out = []
    for m in field.markers:
        to_cam = cam_pos - m.position
        dist = float(np.linalg.norm(to_cam))
        if dist > max_distance or float(np.dot(to_cam, m.normal)) <= 0:
            continue
        uv, z = project(m.corners, T_world_cam, K)
        if np.any(z < 0.02):
            continue
        if np.any(uv < margin_px) or np.any(uv[:, 0] > camera.width - 1 - margin_px) or \
                np.any(uv[:, 1] > camera.height - 1 - margin_px):
            continue
        side = np.linalg.norm(np.roll(uv, -1, axis=0) - uv, axis=1).min()
        if side < min_side_px:
            continue
        out.append(VisibleMarker(m.id, uv, dist))
    return out


class SceneRenderer:
    """Renders the field's markers as the robot's camera sees them. Keeps the marker images cached."""

    def __init__(self, field: Field, camera: CameraSpec, module_px: int = 16, supersample: int = 2,
                 floor_grey: int = 150, plate_grey: int = 235, black: int = 25):
        self.field, self.camera = field, camera
        self.ss = int(supersample)
        self.floor_grey = floor_grey
        from .detect import aruco_dictionary

        d = aruco_dictionary(field.dictionary)
        self._src: dict[int, np.ndarray] = {}
        n = MODULES * module_px
        for m in field.markers:
            img = cv2.aruco.generateImageMarker(d, m.id, n, borderBits=1)
            img = np.where(img > 127, plate_grey, black).astype(np.uint8)
            q = QUIET * module_px
            self._src[m.id] = cv2.copyMakeBorder(img, q, q, q, q, cv2.BORDER_CONSTANT, value=plate_grey)
        self._src_px = n + 2 * QUIET * module_px
        self._plate_scale = (MODULES + 2 * QUIET) / MODULES

    def _plate_corners(self, m: Marker) -> np.ndarray:
        local = CORNER_UNITS * m.size * self._plate_scale
        return local @ m.rotation.T + m.position

    def render(self, pose: tuple[float, float, float] | None = None, T_world_cam: np.ndarray | None = None,
               blur_sigma: float = 0.0, noise_sigma: float = 0.0, rng: np.random.Generator | None = None,
               max_distance: float = 2.5) -> np.ndarray:
        """HxWx3 BGR uint8 image from the robot at ``pose`` (x, y, theta) or the camera at ``T_world_cam``."""
        cam = self.camera
        if T_world_cam is None:
            T_world_cam = camera_world_pose(cam, pose)
        s = self.ss
        W, H = cam.width * s, cam.height * s
        canvas = np.full((H, W), self.floor_grey, dtype=np.float32)
        cam_pos = T_world_cam[:3, 3]
        S = float(self._src_px)
        src = np.array([[-0.5, -0.5], [S - 0.5, -0.5], [S - 0.5, S - 0.5], [-0.5, S - 0.5]], dtype=np.float32)
        order = sorted(self.field.markers, key=lambda m: -np.linalg.norm(cam_pos - m.position))
        for m in order:
            to_cam = cam_pos - m.position
            dist = float(np.linalg.norm(to_cam))
            if dist > max_distance or float(np.dot(to_cam, m.normal)) <= 0:
                continue
            uv, z = project(self._plate_corners(m), T_world_cam, cam.K)
            if np.any(z < 0.02):
                continue
            dst = (s * (uv + 0.5) - 0.5).astype(np.float32)
            x0, y0 = np.floor(dst.min(axis=0)).astype(int) - 1
            x1, y1 = np.ceil(dst.max(axis=0)).astype(int) + 2
            x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
            if x1 <= x0 or y1 <= y0:
                continue
            Hm = cv2.getPerspectiveTransform(src, dst - np.array([x0, y0], dtype=np.float32))
            size = (int(x1 - x0), int(y1 - y0))
            patch = cv2.warpPerspective(self._src[m.id], Hm, size, flags=cv2.INTER_LINEAR,
                                        borderMode=cv2.BORDER_CONSTANT, borderValue=0).astype(np.float32)
            mask = cv2.warpPerspective(np.full((self._src_px, self._src_px), 1.0, np.float32), Hm, size,
                                       flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            roi = canvas[y0:y1, x0:x1]
            roi[:] = roi * (1 - mask) + patch
        img = cv2.resize(canvas, (cam.width, cam.height), interpolation=cv2.INTER_AREA) if s > 1 else canvas
        if blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
        if noise_sigma > 0:
            rng = rng or np.random.default_rng(0)
            img = img + rng.normal(0, noise_sigma, img.shape).astype(np.float32)
        grey = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
