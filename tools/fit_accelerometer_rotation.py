"""Fit the camera-from-accelerometer rotation `R_ci` of a TUM RGB-D folder's accelerometer.txt (no gyro)
against its mocap ground truth: `formats.datasets.PUBLISHED_ACCELEROMETER_R_CI` holds the result for fr1.

    python tools/fit_accelerometer_rotation.py /work/data/rgbd_dataset_freiburg1_rpy_train

At each ground-truth instant the accelerometer's mean over `--window-s` measures up in the camera frame,
`R_wc^T e_z` (the mocap world's z is up: 0.45 deg from the fitted up on the fr1 rpy training frames);
quiet instants (|a| within 0.3 m/s^2 of g, rms deviation under 0.5 m/s^2) are solved by Kabsch
(`Rotation.align_vectors`). Prints the rotation, its rotation vector, its angle from the Kinect's bare
axes (x, y negated), the median residual with each, and the fits of the two halves apart. Fit on the
training frames only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.drivers.imu_checks import G_M_S2
from uareme_fusion.formats.datasets import KINECT_ACCELEROMETER_AXES
from uareme_fusion.formats.tum import read_tum_accelerometer


def quiet_pairs(t_a, accel, t_gt, R_wc, window_s):
    """(accelerometer directions (n, 3), true up in the camera (n, 3)) at the quiet ground-truth instants."""
    dirs, ups = [], []
    for t, R in zip(t_gt, R_wc):
        m = np.abs(t_a - t) <= window_s / 2
        if m.sum() < 5:
            continue
        mean = accel[m].mean(axis=0)
        shake = np.sqrt(((accel[m] - mean) ** 2).sum(axis=1).mean())
        if abs(np.linalg.norm(mean) - G_M_S2) < 0.3 and shake < 0.5:
            dirs.append(mean / np.linalg.norm(mean))
            ups.append(R[2])
    return np.array(dirs), np.array(ups)


def fit(dirs, ups):
    """(R_ci, median residual deg) of up_c = R_ci dir_i."""
    rot, _ = Rotation.align_vectors(ups, dirs)
    return rot.as_matrix(), residual_deg(rot.as_matrix(), dirs, ups)


def residual_deg(R_ci, dirs, ups):
    return float(np.median(np.degrees(np.arccos(np.clip(np.sum(ups * (dirs @ R_ci.T), axis=1), -1, 1)))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--window-s", type=float, default=0.05)
    args = parser.parse_args()
    t_a, accel = read_tum_accelerometer(args.folder / "accelerometer.txt")
    gt = np.loadtxt(args.folder / "groundtruth.txt")
    R_wc = Rotation.from_quat(gt[:, 4:8]).as_matrix()
    dirs, ups = quiet_pairs(t_a, accel, gt[:, 0], R_wc, args.window_s)
    R_ci, res = fit(dirs, ups)
    half = len(dirs) // 2
    R_a, _ = fit(dirs[:half], ups[:half])
    R_b, _ = fit(dirs[half:], ups[half:])
    print(f"quiet instants {len(dirs)}\nR_ci =\n{np.array2string(R_ci, precision=4)}")
    print(f"rotation vector {np.array2string(Rotation.from_matrix(R_ci).as_rotvec(), precision=5)}")
    print(f"from the Kinect axes diag(-1, -1, 1): "
          f"{np.degrees(Rotation.from_matrix(KINECT_ACCELEROMETER_AXES.T @ R_ci).magnitude()):.2f} deg")
    print(f"median residual: fitted {res:.2f} deg, Kinect axes {residual_deg(KINECT_ACCELEROMETER_AXES, dirs, ups):.2f} deg")
    print(f"halves fit {np.degrees(Rotation.from_matrix(R_a.T @ R_b).magnitude()):.2f} deg apart")


if __name__ == "__main__":
    main()
