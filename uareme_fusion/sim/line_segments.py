"""Synthetic line segments of a Manhattan scene seen by a pinhole camera, for tests and benchmarks.

Conventions: `R_cm` has the Manhattan axes as columns in the camera frame (OpenCV: x right, y down,
z forward); `K` maps camera rays to pixels. Segments are returned as `LineSegments` (full-resolution
pixels, weights from length as the detector gives them, contrast 1).
"""

from __future__ import annotations

import numpy as np

from ..solver.line_detection import LineSegments


def manhattan_segments(R_cm: np.ndarray, K: np.ndarray, width: int, height: int, per_axis=(30, 30, 30),
                       noise_px: float = 0.5, clutter: int = 0, length_m: tuple[float, float] = (0.5, 2.0),
                       rng: np.random.Generator | None = None) -> LineSegments:
    """`per_axis[k]` segments along Manhattan axis k (3D segments at 2-12 m in front of the camera,
    kept when both ends are in the image), `clutter` segments in random directions, end points
    perturbed by Gaussian noise of `noise_px` pixels."""
    rng = rng or np.random.default_rng(0)
    R_cm, K = np.asarray(R_cm, float), np.asarray(K, float)
    directions = [R_cm[:, k] for k, n in enumerate(per_axis) for _ in range(n)]
    for _ in range(clutter):
        d = rng.normal(size=3)
        directions.append(d / np.linalg.norm(d))
    out = []
    for d in directions:
        for _ in range(50):  # rejection sampling: both ends inside the image
            pixel = rng.uniform([0, 0], [width - 1, height - 1])
            centre = np.linalg.solve(K, np.append(pixel, 1.0)) * rng.uniform(2.0, 12.0)
            half = 0.5 * rng.uniform(*length_m) * d
            ends = np.stack([centre - half, centre + half])
            if np.any(ends[:, 2] <= 0.1):
                continue
            px = (ends @ K.T)[:, :2] / (ends @ K.T)[:, 2:]
            if np.all((px >= 0) & (px <= [width - 1, height - 1])) and np.linalg.norm(px[1] - px[0]) > 15:
                out.append(px + rng.normal(scale=noise_px, size=(2, 2)))
                break
    ends = np.array(out).reshape(-1, 2, 2)
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    return LineSegments(ends, length / np.hypot(width, height), height, width)
