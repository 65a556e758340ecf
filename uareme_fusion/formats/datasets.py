"""Published camera intrinsics of the datasets this project reads, and their frame conventions.

All matrices are (3, 3) pinhole K in pixels for 640x480 images; distortion in OpenCV's radtan order
(k1, k2, p1, p2, k3), empty for none. ICL-NUIM publishes fy = -480 for a camera frame with y up;
`ICL_NUIM_K_OPENCV` holds the same pixels in OpenCV's y-down frame (fy = +480), and ground-truth
rotations need `flip_y_rotation` to match it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..pinhole import pinhole
from .depth_png import MILLIMETRE_DEPTH_UNIT_M, read_depth_png


ICL_NUIM_K_PUBLISHED = pinhole(481.20, -480.00, 319.50, 239.50)
"""ICL-NUIM intrinsics as published: fy < 0 means the dataset's camera y axis points UP."""
ICL_NUIM_K_OPENCV = pinhole(481.20, 480.00, 319.50, 239.50)
"""The same pixels in the OpenCV camera frame (y down): fy = +480. Its rotations need `flip_y_rotation`."""
ICSL_CORRIDOR_K = pinhole(537.60, 539.03, 316.15, 245.52)
"""ICSL corridor RGB-D camera (millimetre depth)."""
ICSL_INVERSE_DEPTH_OFFSET_PER_M = 0.014
"""What the ICSL depth PNGs add to the inverse depth (1/m), fitted from the depth alone (parallel planes
made parallel: `tools/check_icsl_reference.py`, evidence in `benchmarks/horizon.py`'s docstring)."""

PUBLISHED_INTRINSICS: dict[str, tuple[np.ndarray, np.ndarray]] = {
    "TUM RGB-D freiburg1": (pinhole(517.3, 516.5, 318.6, 255.3), np.array([0.2624, -0.9531, -0.0054, 0.0026, 1.1633])),
    "TUM RGB-D freiburg2": (pinhole(520.9, 521.0, 325.1, 249.7), np.array([0.2312, -0.7849, -0.0033, -0.0001, 0.9172])),
    "TUM RGB-D freiburg3": (pinhole(535.4, 539.2, 320.1, 247.6), np.zeros(0)),
    "ICL-NUIM": (ICL_NUIM_K_OPENCV, np.zeros(0)),
}
"""(K, distortion) that datasets publish, by dataset name (ICL-NUIM in OpenCV axes)."""

KINECT_ACCELEROMETER_AXES = np.diag([-1.0, -1.0, 1.0])
"""A Kinect's accelerometer axes seen from its RGB camera: x and y negated (`v_c = R_ci v_i`)."""

PUBLISHED_ACCELEROMETER_R_CI: dict[str, np.ndarray] = {
    # Fitted on the fr1 rpy training frames (the first 516; tools/fit_accelerometer_rotation.py): the
    # 0.05 s mean accelerometer direction against the mocap's up at 646 quiet instants, median residual
    # 1.53 deg (4.18 with the Kinect's bare axes, 4.63 deg away); the two halves fit 1.3 deg apart.
    "TUM RGB-D freiburg1": Rotation.from_rotvec([0.09384, -0.08265, -3.12684]).as_matrix(),
    "TUM RGB-D freiburg2": KINECT_ACCELEROMETER_AXES,  # the Kinect's axes, not fitted (no fr2 data here)
}
"""Camera-from-accelerometer rotation `R_ci` of the datasets whose `accelerometer.txt` has no gyro, by
dataset name (as `PUBLISHED_INTRINSICS`)."""

RENDERED_DEPTH_DATASETS = frozenset({"ICL-NUIM"})
"""Datasets of `PUBLISHED_INTRINSICS` whose depth maps are rendered, not measured (`SourceInfo.depth_rendered`)."""

FLIP_Y = np.diag([1.0, -1.0, 1.0])
"""The reflection between a y-up camera frame (negative published fy) and OpenCV's y-down frame."""


def flip_y_rotation(R_wc_published: np.ndarray) -> np.ndarray:
    """Camera-to-world rotations of a dataset with negative published fy, in the OpenCV camera frame.

    A negative fy means the dataset's camera frame c' has y up: `p_c = FLIP_Y p_c'` with FLIP_Y =
    diag(1, -1, 1), a reflection. `R_wc' @ FLIP_Y` has det -1, so the world must be reflected too:
    we return `FLIP_Y @ R_wc' @ FLIP_Y` (..., 3, 3), a proper rotation from the OpenCV camera frame
    to the dataset's world mirrored in its y axis. Any constant proper rotation of that world is
    absorbed by the ARE alignment, and rotation errors keep their size.
    """
    return FLIP_Y @ np.asarray(R_wc_published, dtype=float) @ FLIP_Y

GT_KAPPA = 100.0
"""kappa of ground-truth normals in simulated sequences (`normals/*.npz`; the paper's cap)."""


def corrected_icsl_depth(depth_m: np.ndarray, offset_per_m: float = ICSL_INVERSE_DEPTH_OFFSET_PER_M) -> np.ndarray:
    """ICSL depth (metres, 0 where missing) with `offset_per_m` taken off its inverse (0 where that leaves
    none)."""
    inverse = np.divide(1.0, depth_m, out=np.zeros_like(depth_m), where=depth_m > 0) - offset_per_m
    return np.divide(1.0, inverse, out=np.zeros_like(depth_m), where=(depth_m > 0) & (inverse > 0))


def read_icsl_depth(path, offset_per_m: float = ICSL_INVERSE_DEPTH_OFFSET_PER_M,
                    expected_shape: tuple[int, int] | None = None) -> np.ndarray:
    """An ICSL corridor depth PNG (millimetres) as float32 metres with `offset_per_m` taken off its inverse
    (0 to read it as stored); `InputError` as `read_depth_png`. Every reader of ICSL depth (the
    benchmark's reference, the normal network's labels, the check tool) goes through here."""
    return corrected_icsl_depth(read_depth_png(path, MILLIMETRE_DEPTH_UNIT_M, expected_shape), offset_per_m)
