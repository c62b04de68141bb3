"""ArUco marker images for the scene's textures (OpenCV's own generator, so detection is exact)."""
from __future__ import annotations

import cv2
import numpy as np

# quiet (white) border around every marker, in marker cells (a 5x5 marker is 7 cells across with its
# black border); one cell is what a printed marker sheet leaves and what the detector needs.
QUIET_CELLS = 1
CELL_PX = 24  # texture pixels per marker cell: 216 px for a whole textured quad


def aruco_dictionary(name: str = "DICT_5X5_100"):
    try:
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    except AttributeError:
        raise ValueError(f"unknown ArUco dictionary {name!r}") from None


def marker_bits(dictionary) -> int:
    return int(dictionary.markerSize)


def marker_texture(marker_id: int, dictionary, cell_px: int = CELL_PX, quiet_cells: int = QUIET_CELLS,
                   background: int = 255) -> np.ndarray:
    """H x W x 3 uint8 RGB image of one marker with its quiet border, top row = the marker's top edge.

    The black square (``bits + 2`` cells) is exactly the marker's nominal size; the returned image is
    ``(bits + 2 + 2*quiet_cells) * cell_px`` pixels a side.
    """
    cells = marker_bits(dictionary) + 2
    img = cv2.aruco.generateImageMarker(dictionary, int(marker_id), cells * cell_px, borderBits=1)
    pad = quiet_cells * cell_px
    img = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=int(background))
    return np.ascontiguousarray(np.repeat(img[:, :, None], 3, axis=2))


def quad_scale(dictionary, quiet_cells: int = QUIET_CELLS) -> float:
    """Side of the textured quad over the marker's nominal (black square) size."""
    cells = marker_bits(dictionary) + 2
    return (cells + 2 * quiet_cells) / cells
