"""SimTwo's camera frames over ZMQ: one raw message per frame, no header, no timestamp.

640 x 480 x 4 bytes, B G R A per pixel, rows in OpenGL order (row 0 is the BOTTOM image row) unless
the ``bottom_up`` setting says otherwise.
"""
from __future__ import annotations

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
