"""The horizon line and the Manhattan vanishing points of a camera, and drawing them on a frame.

Conventions: camera frame OpenCV (x right, y down, z forward); `up_c` is world up in the camera
frame (`Estimate.up_c`); `R_cm` maps Manhattan coordinates to camera coordinates (its columns are
the scene's axes seen from the camera). Pixels (x, y) have their centres at integers, y down.
The horizon is the image of the plane through the camera centre perpendicular to up: the pixels p
with `up_c . K^-1 p = 0`, i.e. the homogeneous line `l = K^-T up_c`. Rays with `up_c . r > 0` point
above the horizontal, so `l . p > 0` on the sky side.
"""

from __future__ import annotations

import cv2
import numpy as np

from ._draw import SHIFT_BITS, fixed_point, outlined_line, outlined_text, stroke_px, text_height_px
from ._validate import check_rgb, check_rotation, check_vector3
from .camera import check_K

HORIZON_RGB = (0, 255, 0)
"""The paper draws the horizon in green."""
AXIS_RGB = ((255, 0, 0), (0, 255, 0), (0, 0, 255))
"""Manhattan axes X, Y, Z drawn red, green, blue (the paper's X-Y-Z to R-G-B colouring)."""
_AT_INFINITY = 1e-12
"""Relative size below which a homogeneous line or point is taken to be at infinity."""

Segment = tuple[tuple[float, float], tuple[float, float]]


def horizon_line(up_c: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Homogeneous image line (3,) of the horizon, `l = K^-T up_c` scaled so that `(l[0], l[1])` has
    unit length when finite; `l . (x, y, 1)` is the signed distance in pixels, positive on the sky side."""
    up_c = check_vector3(up_c, "up_c")
    line = np.linalg.solve(check_K(K).T, up_c)
    norm = np.hypot(line[0], line[1])
    return line / norm if norm > _AT_INFINITY * abs(line[2]) else line


def horizon_segment(up_c: np.ndarray, K: np.ndarray, height: int, width: int) -> Segment | None:
    """The horizon clipped to the image `[0, width-1] x [0, height-1]`: `((x0, y0), (x1, y1))` in
    pixels, ordered so that the sky lies on the left of the direction p0 -> p1 as seen in the image
    (a level camera gives a left-to-right segment). None when the horizon misses the image, e.g. a
    camera looking straight up or down (the line is then at infinity)."""
    line = horizon_line(up_c, K)
    if np.hypot(line[0], line[1]) <= _AT_INFINITY * abs(line[2]):
        return None
    return _clip_line(line, height, width)


def on_sky_side(points_xy: np.ndarray, up_c: np.ndarray, K: np.ndarray) -> np.ndarray:
    """For pixels (..., 2) as (x, y): True where the pixel's ray points above the horizontal."""
    points_xy = np.asarray(points_xy, dtype=float)
    line = horizon_line(up_c, K)
    return points_xy @ line[:2] + line[2] > 0.0


def manhattan_vanishing_points(R_cm: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Vanishing points (3, 2) in pixels of the Manhattan axes X, Y, Z (rows), `p ~ K @ R_cm[:, k]`;
    the same point for +axis and -axis. A row is NaN when that axis is parallel to the image plane
    (its vanishing point is at infinity)."""
    R_cm = check_rotation(R_cm, "R_cm")
    homogeneous = (check_K(K) @ R_cm).T  # (3 axes, 3)
    points = np.full((3, 2), np.nan)
    finite = np.abs(homogeneous[:, 2]) > _AT_INFINITY * np.linalg.norm(homogeneous[:, :2], axis=1)
    points[finite] = homogeneous[finite, :2] / homogeneous[finite, 2:3]
    return points


def draw_horizon(
    rgb: np.ndarray,
    up_c: np.ndarray,
    K: np.ndarray,
    fov_note: str | None = None,
    colour_rgb: tuple[int, int, int] = HORIZON_RGB,
    std_px: float | None = None,
    known: bool = True,
) -> np.ndarray:
    """A copy of `rgb` (H, W, 3) uint8 with the horizon drawn anti-aliased, a short tick at its middle
    pointing to the sky, and `fov_note` (e.g. `camera.assumed_fov_note()`) written bottom-left when
    given. `std_px`: its standard deviation along its normal, drawn as a shaded band of +-1 std with
    thin edges. When the horizon misses the image, "horizon off-screen" and where it lies (above,
    below, left or right, and how far from the centre) is written top-left instead; when not `known`,
    nothing is drawn but the note "horizon unknown"."""
    image = check_rgb(rgb).copy()
    height, width = image.shape[:2]
    up_c = check_vector3(up_c, "up_c")
    if not known:
        outlined_text(image, "horizon unknown (no structure or sky fixes it)", (8, 8 + text_height_px(image)), colour_rgb)
        if fov_note:
            outlined_text(image, fov_note, (8, height - 8))
        return image
    segment = horizon_segment(up_c, K, height, width)
    thickness = stroke_px(height, width)
    band = std_px is not None and np.isfinite(std_px) and std_px >= 1.0
    if band:
        _draw_band(image, horizon_line(up_c, K), float(std_px), colour_rgb, max(thickness // 2, 1))
    if segment is None:
        outlined_text(image, off_screen_note(up_c, K, height, width), (8, 8 + text_height_px(image)), colour_rgb)
    else:
        p0, p1 = np.asarray(segment[0]), np.asarray(segment[1])
        outlined_line(image, p0, p1, colour_rgb, thickness)
        direction = (p1 - p0) / max(np.linalg.norm(p1 - p0), 1e-9)
        sky_normal = np.array([direction[1], -direction[0]])  # the left of p0 -> p1 in the image
        middle = (p0 + p1) / 2.0
        outlined_line(image, middle, middle + 0.04 * min(height, width) * sky_normal, colour_rgb, thickness)
    if fov_note:
        outlined_text(image, fov_note, (8, height - 8))
    return image


def off_screen_note(up_c: np.ndarray, K: np.ndarray, height: int, width: int) -> str:
    """"horizon off-screen, N px above" (below, left, right: where its nearest point to the image centre
    lies, N its distance from the centre), or "horizon at infinity" for a camera looking straight up or down."""
    a, b, c = horizon_line(up_c, K)
    norm = np.hypot(a, b)
    if norm <= _AT_INFINITY * abs(c):
        return "horizon off-screen (at infinity: camera looking straight up or down)"
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    dist = (a * centre[0] + b * centre[1] + c) / norm  # > 0: the centre is on the sky side
    foot = centre - dist * np.array([a, b]) / norm
    d = foot - centre
    where = ("below" if d[1] > 0 else "above") if abs(d[1]) >= abs(d[0]) else ("right" if d[0] > 0 else "left")
    return f"horizon off-screen, {abs(dist):.0f} px {where} the centre"


def _draw_band(image: np.ndarray, line: np.ndarray, std_px: float, colour_rgb, thickness: int) -> None:
    """Shade the pixels within `std_px` of `line` (a x + b y + c = 0, [a, b] unit) and draw the band's edges, in place."""
    height, width = image.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width]
    inside = np.abs(line[0] * xs + line[1] * ys + line[2]) <= std_px
    if inside.any():
        tint = np.asarray(colour_rgb, np.float32)
        image[inside] = (0.75 * image[inside] + 0.25 * tint).astype(np.uint8)
    for shift in (-std_px, std_px):
        edge = np.array([line[0], line[1], line[2] + shift])
        seg = _clip_line(edge, height, width)
        if seg is not None:
            cv2.line(image, fixed_point(seg[0]), fixed_point(seg[1]), colour_rgb, thickness, cv2.LINE_AA, SHIFT_BITS)


def _clip_line(line: np.ndarray, height: int, width: int) -> Segment | None:
    """A line a x + b y + c = 0 ([a, b] unit) clipped to the image `[0, width-1] x [0, height-1]` by
    Liang-Barsky, ordered so that its positive side lies on the left of p0 -> p1; None when it misses."""
    a, b, c = line
    p_foot = -c * np.array([a, b])
    d = np.array([-b, a])
    t_lo, t_hi = -np.inf, np.inf
    for p, q in ((-d[0], p_foot[0]), (d[0], width - 1 - p_foot[0]), (-d[1], p_foot[1]), (d[1], height - 1 - p_foot[1])):
        if p == 0.0:
            if q < 0.0:
                return None
            continue
        t = q / p
        if p < 0.0:
            t_lo = max(t_lo, t)
        else:
            t_hi = min(t_hi, t)
    if not t_hi > t_lo:
        return None
    p0, p1 = p_foot + t_lo * d, p_foot + t_hi * d
    return (float(p0[0]), float(p0[1])), (float(p1[0]), float(p1[1]))


def draw_manhattan_axes(
    rgb: np.ndarray, R_cm: np.ndarray, K: np.ndarray, length_frac: float = 0.15
) -> np.ndarray:
    """A copy of `rgb` (H, W, 3) uint8 with the Manhattan axes drawn as X-Y-Z = red-green-blue arrows
    from the image centre, in perspective: a triad on the centre pixel's ray at unit depth, its arrows
    about `length_frac * min(H, W)` pixels long when parallel to the image plane (nearer arrows drawn
    last), plus a ring at each axis's vanishing point that falls inside the image."""
    image = check_rgb(rgb).copy()
    R_cm = check_rotation(R_cm, "R_cm")
    K = check_K(K)
    height, width = image.shape[:2]
    thickness = stroke_px(height, width)
    origin_c = np.linalg.solve(K, [(width - 1) / 2.0, (height - 1) / 2.0, 1.0])  # depth 1
    length = min(0.5, length_frac * min(height, width) / K[0, 0])  # <= 0.5 keeps tips in front
    tips_c = origin_c[:, None] + length * R_cm  # (3, 3 axes)
    tips_px = (K @ tips_c)[:2] / (K @ tips_c)[2]
    origin_px = fixed_point(((width - 1) / 2.0, (height - 1) / 2.0))
    for k in np.argsort(-tips_c[2]):  # farthest tip first
        tip = fixed_point(tips_px[:, k])
        cv2.arrowedLine(image, origin_px, tip, (0, 0, 0), thickness + 2, cv2.LINE_AA, SHIFT_BITS, 0.2)
        cv2.arrowedLine(image, origin_px, tip, AXIS_RGB[k], thickness, cv2.LINE_AA, SHIFT_BITS, 0.2)
    radius = 4 * thickness
    for k, point in enumerate(manhattan_vanishing_points(R_cm, K)):
        if np.all(np.isfinite(point)) and 0 <= point[0] <= width - 1 and 0 <= point[1] <= height - 1:
            centre = fixed_point(point)
            cv2.circle(image, centre, radius << SHIFT_BITS, (0, 0, 0), thickness + 2, cv2.LINE_AA, SHIFT_BITS)
            cv2.circle(image, centre, radius << SHIFT_BITS, AXIS_RGB[k], thickness, cv2.LINE_AA, SHIFT_BITS)
    return image
