"""Drawing what the estimator knows: the horizon, the Manhattan axes, normal/confidence panes and
ground masks, on RGB uint8 frames (every drawing function returns a new image).

Conventions: camera frame OpenCV (x right, y down, z forward); `up_c` is world up in the camera
frame; `R_cm` maps Manhattan to camera coordinates; K is in pixels with pixel centres at integers.
"""

from .camera import DEFAULT_FOV_DEG, assumed_fov_note, assumed_K, check_K, intrinsics_or_assumed
from .compose import draw_overlay
from .ground import draw_ground, ground_mask
from .horizon import (
    draw_horizon,
    draw_manhattan_axes,
    horizon_line,
    horizon_segment,
    manhattan_vanishing_points,
    on_sky_side,
)
from .panes import confidence_to_rgb, side_by_side

__all__ = [
    "DEFAULT_FOV_DEG",
    "assumed_K",
    "assumed_fov_note",
    "check_K",
    "confidence_to_rgb",
    "draw_ground",
    "draw_horizon",
    "draw_manhattan_axes",
    "draw_overlay",
    "ground_mask",
    "horizon_line",
    "horizon_segment",
    "intrinsics_or_assumed",
    "manhattan_vanishing_points",
    "on_sky_side",
    "side_by_side",
]
