"""SimTwo's camera frames over ZMQ: one raw message per frame, no header, no timestamp.

640 x 480 x 4 bytes, B G R A per pixel, rows in OpenGL order (row 0 is the BOTTOM image row) unless
the ``bottom_up`` setting says otherwise. ``raf sim --paced`` (docs/pacing.md) sends each frame as two ZMQ
parts instead: a header with the frame's simulation time and index (:func:`camera_header`), then this payload.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ProtocolError

WIDTH = 640
HEIGHT = 480
CHANNELS = 4
FRAME_BYTES = WIDTH * HEIGHT * CHANNELS  # 1,228,800


def decode_frame(data: bytes | memoryview, width: int = WIDTH, height: int = HEIGHT,
                 bottom_up: bool = True) -> np.ndarray:
    """Raw B G R A bytes to a C-contiguous ``height x width x 3`` uint8 BGR image (top row first)."""
    expected = width * height * CHANNELS
    n = len(data)
    if n != expected:
        raise ProtocolError(f"camera frame of {n} bytes; expected exactly {width}*{height}*4 = {expected} "
                            "(B G R A, no header)")
    bgra = np.frombuffer(data, dtype=np.uint8).reshape(height, width, CHANNELS)
    if bottom_up:
        bgra = bgra[::-1]
    return np.ascontiguousarray(bgra[:, :, :3])


def encode_frame(bgr: np.ndarray, bottom_up: bool = True) -> bytes:
    """A ``height x width x 3`` uint8 BGR image (top row first) to SimTwo's raw B G R A bytes (A = 255)."""
    if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
        raise ProtocolError(f"expected an HxWx3 uint8 BGR image, got shape {bgr.shape} dtype {bgr.dtype}")
    h, w, _ = bgr.shape
    out = np.empty((h, w, 4), dtype=np.uint8)
    src = bgr[::-1] if bottom_up else bgr
    out[:, :, :3] = src
    out[:, :, 3] = 255
    return out.tobytes()


#: paced runs send each camera frame as two ZMQ parts: this header, then SimTwo's payload
CAMERA_HEADER = b"raf-camera-frame"


def camera_header(t: float, index: int) -> bytes:
    """A paced camera frame's first part: ``raf-camera-frame <simulation time s> <index>``."""
    return b"%s %.6f %d" % (CAMERA_HEADER, t, index)


def parse_camera_header(data: bytes) -> tuple[float, int] | None:
    """(time s, index) of a paced camera frame's header, or None if ``data`` is not one."""
    parts = bytes(data).split()
    if len(parts) != 3 or parts[0] != CAMERA_HEADER:
        return None
    try:
        t, i = float(parts[1]), int(parts[2])
    except ValueError:
        return None
    return (t, i) if math.isfinite(t) and i >= 0 else None
