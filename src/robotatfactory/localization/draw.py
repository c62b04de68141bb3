"""The debug image: detected markers outlined with their IDs and axes (like the paper's figure 6), rejected
detections in red with the reason, and the pose estimates as text. Pure OpenCV, no ROS."""
from __future__ import annotations

import math

import cv2
import numpy as np

from .geometry import matrix_rt
from .pipeline import FrameResult

GREEN, RED, YELLOW, WHITE, BLACK = (0, 200, 0), (0, 0, 255), (0, 220, 255), (255, 255, 255), (0, 0, 0)


def _text(img, s, org, color=WHITE, scale=0.45):
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, scale, BLACK, 3, cv2.LINE_AA)
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)


def draw_debug(image: np.ndarray, res: FrameResult, K: np.ndarray, axis_m: float = 0.03,
               filter_pose: tuple[float, float, float] | None = None, method: str = "planar") -> np.ndarray:
    """A copy of ``image`` (BGR) with the frame's detections, axes and estimates drawn on it."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    used = set()
    e = res.estimates.get(method)
    if e is not None and e.ok:
        used = set(e.marker_ids)
    for o in res.observations:
        c = o.corners.reshape(1, 4, 2).astype(np.float32)
        color = GREEN if (o.id in used or not used) else YELLOW
        cv2.aruco.drawDetectedMarkers(out, [c], np.array([[o.id]]), borderColor=color)
        i = o.checked if o.checked is not None else 0
        rvec, tvec = matrix_rt(o.solutions[i])
        try:
            cv2.drawFrameAxes(out, K, None, rvec, tvec, min(axis_m, o.marker.size), 2)
        except cv2.error:
            pass
    why = dict(res.rejected)
    for d in res.detections:
        if d.id in why:
            pts = d.corners.astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(out, [pts], True, RED, 2, cv2.LINE_AA)
            p = d.corners.min(axis=0).astype(int)
            _text(out, f"{d.id}: {why[d.id]}", (int(p[0]), max(12, int(p[1]) - 4)), RED)
    y = 18
    for name, est in res.estimates.items():
        if est.ok:
            s = (f"{name}: x {est.base[0]:+.3f} y {est.base[1]:+.3f} th {math.degrees(est.base[2]):+.1f} "
                 f"sd {est.sigma_xy * 1000:.1f} mm  ids {','.join(map(str, est.marker_ids))}")
            _text(out, s, (8, y), GREEN if name == method else WHITE)
        else:
            _text(out, f"{name}: rejected ({est.reason})", (8, y), RED)
        y += 18
    if filter_pose is not None:
        _text(out, f"ekf: x {filter_pose[0]:+.3f} y {filter_pose[1]:+.3f} th {math.degrees(filter_pose[2]):+.1f}",
              (8, y), YELLOW)
    return out
