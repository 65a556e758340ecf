"""Synthetic Manhattan normal maps with controlled noise, outliers and visible axes.

For solver tests, covariance calibration, the benchmark and the built-in demo: no rendering, just
piecewise-constant normals from a random partition of the image into planes, each plane facing the
camera along one Manhattan axis.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..rotations import exp_so3
from ..types import NormalMap


def manhattan_normal_map(
    R_cm: np.ndarray,
    rng: np.random.Generator,
    height: int = 120,
    width: int = 160,
    axes: tuple[int, ...] = (0, 1, 2),
    noise_deg: float = 10.0,
    correlation_px: float = 0.0,
    outlier_fraction: float = 0.0,
    outlier_kappa: float = 0.1,
    n_planes: int = 12,
    dtype=np.float32,
) -> NormalMap:
    """A (height, width) map whose pixels are the Manhattan axes `R_cm[:, axes]` (signed to face the
    camera), perturbed by angular noise of `noise_deg` standard deviation per tangent direction,
    spatially correlated over `correlation_px` (Gaussian sigma, 0 for white), with a fraction of
    random-direction outliers carrying kappa `outlier_kappa` (inliers carry 1).
    """
    R_cm = np.asarray(R_cm, float)
    seeds = rng.uniform([0, 0], [width, height], size=(n_planes, 2))
    # Squared distance of each pixel to each seed, (height, width, n_planes), summed from its two
    # separable parts (the same numbers as from a pixel grid, without the grid).
    dx2 = (np.arange(width)[:, None] - seeds[:, 0]) ** 2
    dy2 = (np.arange(height)[:, None] - seeds[:, 1]) ** 2
    plane = np.argmin(dx2[None, :, :] + dy2[:, None, :], axis=-1)
    plane_axis = np.asarray(axes)[np.arange(n_planes) % len(axes)]
    directions = R_cm[:, plane_axis].T  # (n_planes, 3)
    directions *= -np.sign(directions[:, 2:3] + 1e-12)  # face the camera (looking along +z)
    normals = directions[plane]

    noise = rng.standard_normal((height, width, 3)).astype(np.float32)
    if correlation_px > 0:
        noise = cv2.GaussianBlur(noise, (0, 0), correlation_px, borderType=cv2.BORDER_REFLECT)
        noise /= noise.reshape(-1, 3).std(axis=0)
    normals = normals + np.radians(noise_deg) * noise
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)

    kappa = np.ones((height, width))
    outliers = rng.random((height, width)) < outlier_fraction
    random_dirs = rng.standard_normal((int(outliers.sum()), 3))
    normals[outliers] = random_dirs / np.linalg.norm(random_dirs, axis=-1, keepdims=True)
    kappa[outliers] = outlier_kappa
    return NormalMap(normals=normals.astype(dtype), kappa=kappa.astype(dtype))


def random_noisy_maps(count: int, seed: int, height: int = 120, width: int = 160):
    """Yield `(R_cm_true, NormalMap)` pairs for covariance calibration and its held-out check.

    Each map: uniformly random rotation, three visible axes, 4-16 planes, angular noise 2-15 deg
    correlated over 2-6 px (at 160 px width; scaled with `width`), 0-20 % outliers with kappa 0.1.
    """
    rng = np.random.default_rng(seed)
    for _ in range(count):
        R_cm = exp_so3(rng.normal(size=3) * 2.0)
        yield R_cm, manhattan_normal_map(
            R_cm,
            rng,
            height=height,
            width=width,
            noise_deg=rng.uniform(2.0, 15.0),
            correlation_px=rng.uniform(2.0, 6.0) * width / 160.0,
            outlier_fraction=rng.uniform(0.0, 0.2),
            n_planes=int(rng.integers(4, 17)),
        )
