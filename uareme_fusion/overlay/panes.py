"""Side-by-side panes for overlay videos: the frame, its normals and their confidence.

Panes follow the paper's demo: normals coloured X-Y-Z to R-G-B (OpenCV camera frame), confidence in
grey with white = confident (kappa / KAPPA_CAP_DISPLAY, clipped to [0, 1]).
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError
from ..io.normal_maps import normals_to_rgb
from ..types import NormalMap
from ._draw import outlined_text, text_height_px
from ._validate import check_rgb

KAPPA_CAP_DISPLAY = 75.0
"""kappa shown as white: the cap of the paper's released configuration."""


def confidence_to_rgb(kappa: np.ndarray, kappa_cap: float = KAPPA_CAP_DISPLAY) -> np.ndarray:
    """kappa (H, W) as a grey RGB uint8 image, 0 black to `kappa_cap` and above white (NaN black)."""
    grey = np.clip(np.nan_to_num(np.asarray(kappa, np.float32) / kappa_cap, nan=0.0), 0.0, 1.0)
    return np.repeat(np.rint(grey * 255.0).astype(np.uint8)[..., None], 3, axis=2)


def side_by_side(
    rgb: np.ndarray,
    normal_map: NormalMap | None,
    include_normals: bool = True,
    include_confidence: bool = True,
) -> np.ndarray:
    """`rgb` (H, W, 3) uint8 (typically an overlay) followed left to right by the requested panes,
    each resized to (H, W) so that a video's frame size never changes: shape (H, W * (1 + panes), 3).
    A frame without normals (`normal_map` None) gets black panes labelled "no normals"."""
    rgb = check_rgb(rgb)
    height, width = rgb.shape[:2]
    if (include_normals or include_confidence) and normal_map is not None:
        if normal_map.normals.shape[:2] != np.shape(normal_map.kappa) or normal_map.normals.ndim != 3:
            raise InputError(
                f"normal map has normals {normal_map.normals.shape} and kappa {np.shape(normal_map.kappa)}; "
                "expected (H, W, 3) and (H, W)"
            )
    panes = [rgb]
    for wanted, label, render in (
        (include_normals, "normals", lambda m: normals_to_rgb(m.normals)),
        (include_confidence, "confidence", lambda m: confidence_to_rgb(m.kappa)),
    ):
        if not wanted:
            continue
        if normal_map is None:
            pane, label = np.zeros_like(rgb), "no normals"
        else:
            pane = cv2.resize(render(normal_map), (width, height), interpolation=cv2.INTER_NEAREST)
        outlined_text(pane, label, (8, 8 + text_height_px(pane)))
        panes.append(pane)
    return np.concatenate(panes, axis=1)
