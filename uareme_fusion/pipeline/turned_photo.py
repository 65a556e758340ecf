"""A photo turned by 90, 180 or 270 deg, answered upright (issue 26 bad input).

The zenith search assumes an upright photo (`ZenithConfig.roll_prior_deg`) and the Manhattan solve is
24-fold symmetric, so in a turned photo the segments take a facade's horizontal VP for the zenith and give
a confident wrong horizon. When a sky boundary contradicts that horizon (`horizon_estimate.
sky_orientation_doubt_deg`), the evidence decides: the photo is analysed again turned by the quarter turns
that bring the boundary's sky side to the image top (`sky_quarters`), and that answer, when its horizon is
known and agrees with the boundary (`TurnConfig.max_sky_angle_deg`), is carried back into the photo's own
pixels and camera frame (`turned_back`); otherwise the photo stays declined.

A clockwise quarter turn maps a pixel (x, y) of an H-row image to (H - 1 - y, x): `x_t = T x` with `T` the
3x3 pixel map, and camera coordinates by `d_t = R_z d` (x_t ~ K_t R_z d, K_t = T K R_z^T). So back in the
photo: R_cm = R_z^T R_cm_t (the right perturbation's covariance unchanged), up_c = R_z^T up_c_t,
K = T^-1 K_t R_z, a line l = T^T l_t, a point x = T^-1 x_t.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TurnConfig:
    """When a sky boundary turns the photo (measured, REAL: `tools/turned_photos.py` on ECD turned by 90, 180
    and 270 deg, chosen on the odd-numbered photos, the even ones held out)."""

    min_separation: float = 1.4
    """The boundary's separation (`SkyHorizon.separation`) from which it may turn the photo: above the 1.35
    that indoor walls and floors reached (every 4th ICSL, ICSL-more and ICL kt3 frame); ECD 076, its sky
    found below at 1.35, would have been turned upside down."""
    max_sky_angle_deg: float = 15.0
    """The turned analysis' horizon must have its up within this (image plane) of the boundary's sky
    direction to be taken (the boundary is too rough to be the horizon, but not to tell where the sky is;
    ECD odd photos: 15 right and none wrong at 15 deg, 3 off by more than 0.05 H at 20 deg)."""


def turned_photo(rgb: np.ndarray, quarters: int) -> np.ndarray:
    """`rgb` turned clockwise by `quarters` x 90 deg (contiguous)."""
    return np.ascontiguousarray(np.rot90(rgb, k=-quarters))


def quarter_turn(height: int, width: int, quarters: int) -> tuple[np.ndarray, np.ndarray]:
    """(T, R_z): the pixel map (3x3, homogeneous) and the camera-frame rotation of a `height` x `width`
    image turned clockwise by `quarters` x 90 deg (`np.rot90(rgb, k=-quarters)`)."""
    T, R = np.eye(3), np.eye(3)
    h = height
    for _ in range(quarters % 4):
        T = np.array([[0.0, -1.0, h - 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ T
        R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ R
        h = width if h == height else height
    return T, R


def sky_quarters(line) -> int:
    """The clockwise quarter turns (1, 2 or 3; 0 when it already is) that bring the sky side of the image
    line `line` ([a, b, c], positive on the sky side) nearest the image top."""
    n = np.asarray(line[:2], float)
    # one clockwise turn carries a direction (dx, dy) to (-dy, dx); image up is (0, -1)
    ups = [n, np.array([-n[1], n[0]]), -n, np.array([n[1], -n[0]])]
    return int(np.argmax([-u[1] for u in ups]))


def mapped_line(line, T: np.ndarray) -> np.ndarray:
    """The image line `line` ([a, b, c]) under the pixel map `T` (x' = T x): T^-T l, [a, b] unit, its
    positive side kept."""
    l = np.linalg.solve(T.T, np.asarray(line, float))
    return l / np.hypot(l[0], l[1])


def turned_back(analysis, rgb: np.ndarray, normal_map, segments, quarters: int):
    """The `ImageAnalysis` of the photo turned by `quarters` carried back into the photo's pixels and
    camera frame, with the photo's own `rgb`, `normal_map` and `segments`."""
    h, w = rgb.shape[:2]
    T, R_z = quarter_turn(h, w, quarters)
    T_inv = np.linalg.inv(T)
    K = T_inv @ analysis.focal.K @ R_z
    K[np.abs(K) < 1e-12] = 0.0
    visual = dataclasses.replace(analysis.visual, R_cm=R_z.T @ analysis.visual.R_cm)
    atlanta = analysis.atlanta
    if atlanta is not None:
        atlanta = dataclasses.replace(atlanta, line_px=mapped_line(atlanta.line_px, T_inv),
                                      zenith_px=T_inv @ atlanta.zenith_px)
    sky = analysis.sky
    if sky is not None:
        sky = dataclasses.replace(sky, line=mapped_line(sky.line, T_inv), height=h, width=w)
    reported = None if analysis.R_cm_reported is None else R_z.T @ analysis.R_cm_reported
    return dataclasses.replace(analysis, rgb=rgb, normal_map=normal_map, segments=segments, visual=visual,
                               up_c=R_z.T @ analysis.up_c, focal=dataclasses.replace(analysis.focal, K=K),
                               atlanta=atlanta, sky=sky, R_cm_reported=reported, turned_deg=90.0 * quarters)
