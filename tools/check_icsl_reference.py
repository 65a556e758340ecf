"""Depth-only checks of the ICSL depth-normal reference of `bench horizon` (issue 12): no RGB estimate
takes part, so the reference is not fitted to the answer it scores.

- Registration: are the depth PNGs in the colour camera's pixels? The depth jumps (near side of a step
  of more than 6 % in depth, within 4 m) are scored against the colour image's Canny edges by their
  mean distance to the nearest edge (truncated at 3 px), over shifts of +-12 px and scales of
  0.98-1.02 about the image centre, then over a radial term k1 (about the published K) at the best
  shift, summed over frames.
- Inverse-depth offset: whole planes (each side of each Manhattan axis, 5000+ px, trimmed least squares
  in inverse depth) fitted after taking an offset b off the inverse depth; the angles between parallel
  planes (should be 0) and between perpendicular ones (should be 90), over b.
- Focal length: in frames turned 12+ deg from the corridor, the angle between the two wall directions
  (kappa-weighted mean normals within 8 deg of each axis, 21 px plane fits) from 90 deg, over f.
- Window: the depth-normal rotation for plane-fit windows of 9 to 31 px; the mean per-frame angle
  between each pair of windows, after the Manhattan symmetry.

Data: ICSL RGB-D corridor (from LPVO, MIT), every second frame of icsl_corridor and icsl_corridor_more.
Usage: python tools/check_icsl_reference.py [--data ../shared/data] [--stride 2]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from uareme_fusion.formats.datasets import (
    ICSL_CORRIDOR_K,
    ICSL_INVERSE_DEPTH_OFFSET_PER_M,
    corrected_icsl_depth,
    read_icsl_depth,
)
from uareme_fusion.normals.depth import DepthNormals, DepthNormalsConfig
from uareme_fusion.pinhole import pinhole
from uareme_fusion.rotations import log_so3, nearest_symmetric
from uareme_fusion.solver import solve_manhattan

SHIFTS_PX = np.arange(-12, 13)
SCALES = np.array([0.98, 0.99, 1.0, 1.01, 1.02])
RADIAL_K1 = np.round(np.arange(-0.15, 0.151, 0.025), 3)
OFFSETS_PER_M = (0.0, 0.005, 0.01, 0.0125, ICSL_INVERSE_DEPTH_OFFSET_PER_M, 0.015, 0.0175, 0.02, 0.03)
FOCALS_PX = (505.0, 520.0, 537.6, 554.0, 570.0)
WINDOWS_PX = (9, 11, 13, 15, 17, 21, 25, 31)
WHOLE_PLANE_WINDOW_PX = 21
"""The plane-fit window of the checks' depth normals (wide: whole planes, little noise)."""


def window_normals(window_px: int = WHOLE_PLANE_WINDOW_PX) -> DepthNormals:
    """Depth normals fitted over `window_px` windows (stride 2 px below 20 px, else 4)."""
    return DepthNormals(DepthNormalsConfig(window_px=window_px, stride_px=2 if window_px < 20 else 4))


def depth_jumps(depth_m: np.ndarray, min_log_step: float = 0.06, max_depth_m: float = 4.0) -> np.ndarray:
    """(N, 2) pixels (u, v) on the near side of a depth step, away from missing depth."""
    valid = depth_m > 0
    log_z = np.log(np.maximum(depth_m, 1e-3))
    jump = np.zeros(depth_m.shape, bool)
    step_u, step_v = log_z[:, 2:] - log_z[:, :-2], log_z[2:] - log_z[:-2]
    jump[:, :-2] |= step_u > min_log_step
    jump[:, 2:] |= step_u < -min_log_step
    jump[:-2] |= step_v > min_log_step
    jump[2:] |= step_v < -min_log_step
    jump &= (cv2.erode(valid.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0) & (depth_m < max_depth_m)
    v, u = np.nonzero(jump)
    return np.stack([u, v], 1).astype(float)


def edge_distance(rgb: np.ndarray, truncate_px: float = 3.0) -> np.ndarray:
    """Distance (px) of every pixel to the nearest colour edge, truncated."""
    gray = cv2.GaussianBlur(cv2.cvtColor(rgb, cv2.COLOR_BGR2GRAY), (5, 5), 1.2)
    return np.minimum(cv2.distanceTransform((cv2.Canny(gray, 20, 50) == 0).astype(np.uint8), cv2.DIST_L2, 3),
                      truncate_px)


def mean_distance(distance: np.ndarray, points: np.ndarray) -> float:
    uv = np.round(points).astype(int)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < distance.shape[1]) & (uv[:, 1] >= 0) & (uv[:, 1] < distance.shape[0])
    return float(distance[uv[inside, 1], uv[inside, 0]].mean())


def registration(rgb_paths: list[Path], depths: list[np.ndarray]) -> str:
    """The shift and scale, then the radial k1 at that shift, that put the depth jumps on colour edges."""
    K = ICSL_CORRIDOR_K
    centre, pp, f = np.array([319.5, 239.5]), K[:2, 2], K[0, 0]
    moved = np.zeros((len(SCALES), len(SHIFTS_PX), len(SHIFTS_PX)))
    seen = []
    for path, depth in zip(rgb_paths, depths):
        points = depth_jumps(depth)
        if len(points) < 100:
            continue
        points = points[np.random.default_rng(0).permutation(len(points))[:4000]]
        distance = edge_distance(cv2.imread(str(path)))
        costs = np.array([[[mean_distance(distance, centre + s * (points - centre) + [dx, dy]) for dy in SHIFTS_PX]
                           for dx in SHIFTS_PX] for s in SCALES])
        moved += costs - costs.mean()
        seen.append((distance, points))
    i, j, k = np.unravel_index(np.argmin(moved), moved.shape)
    shift = np.array([SHIFTS_PX[j], SHIFTS_PX[k]])
    radial = np.zeros(len(RADIAL_K1))
    for distance, points in seen:
        x = (points - pp) / f
        costs = np.array([mean_distance(distance, pp + f * x * (1 + k1 * (x**2).sum(1, keepdims=True)) + shift)
                          for k1 in RADIAL_K1])
        radial += costs - costs.mean()
    return (f"registration ({len(seen)} frames with depth jumps): best shift ({shift[0]}, {shift[1]}) px, scale "
            f"{SCALES[i]:.2f}, radial k1 {RADIAL_K1[np.argmin(radial)]:+.3f}")


def whole_planes(depth_m: np.ndarray, K: np.ndarray, min_px: int = 5000) -> list[tuple[int, np.ndarray]]:
    """(axis, unit normal) of each plane: pixels within 10 deg of a Manhattan axis (21 px fits), split by
    the side of the camera they lie on, fitted as 1/z = g . ray (three rounds, keeping the 80 % best)."""
    h, w = depth_m.shape
    nm = window_normals().estimate(depth_m, K)
    R = solve_manhattan(nm).R_cm
    v, u = np.mgrid[0:h, 0:w]
    rays = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3).astype(float) @ np.linalg.inv(K).T
    z, n = depth_m.ravel(), nm.normals.reshape(-1, 3)
    usable = (z > 0.3) & (z < 6.0) & (nm.kappa.ravel() > 0)
    planes = []
    for axis in range(3):
        near = usable & (np.abs(n @ R[:, axis]) > np.cos(np.radians(10.0)))
        side = np.sign((rays * z[:, None]) @ R[:, axis])
        for sign in (-1, 1):
            idx = np.nonzero(near & (side == sign))[0]
            if len(idx) < min_px:
                continue
            for _ in range(3):
                g = np.linalg.lstsq(rays[idx], 1.0 / z[idx], rcond=None)[0]
                residual = np.abs(rays[idx] @ g - 1.0 / z[idx])
                idx = idx[residual < np.percentile(residual, 80)]
            planes.append((axis, g / np.linalg.norm(g)))
    return planes


def plane_pair_angles(depths: list[np.ndarray], offset_per_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Angles (deg) between parallel plane pairs, and of perpendicular pairs from 90, over all frames."""
    parallel, perpendicular = [], []
    for depth in depths:
        planes = whole_planes(corrected_icsl_depth(depth, offset_per_m), ICSL_CORRIDOR_K)
        for i, (axis_a, a) in enumerate(planes):
            for axis_b, b in planes[i + 1:]:
                angle = np.degrees(np.arccos(min(abs(float(a @ b)), 1.0)))
                (parallel if axis_a == axis_b else perpendicular).append(angle if axis_a == axis_b else 90.0 - angle)
    return np.array(parallel), np.array(perpendicular)


def wall_angle_deg(depth_m: np.ndarray, K: np.ndarray, R: np.ndarray, gate_deg: float = 8.0) -> float | None:
    """The two horizontal axes' directions (kappa-weighted mean normals within `gate_deg`, 21 px fits)
    angle from 90 deg; None when either has fewer than 2000 pixels."""
    nm = window_normals().estimate(depth_m, K)
    n, weight = nm.normals.reshape(-1, 3), nm.kappa.ravel()
    vertical = int(np.argmax(np.abs(R[1])))
    means = []
    for axis in (k for k in range(3) if k != vertical):
        direction = R[:, axis]
        for _ in range(2):
            dot = n @ direction
            near = (np.abs(dot) > np.cos(np.radians(gate_deg))) & (weight > 0)
            if near.sum() < 2000:
                return None
            direction = (np.sign(dot[near])[:, None] * n[near] * weight[near, None]).sum(0)
            direction /= np.linalg.norm(direction)
        means.append(direction)
    return float(np.degrees(np.arcsin(abs(means[0] @ means[1]))))


def mean_angle_deg(R_a: list, R_b: list) -> float:
    """Mean over frames of the angle between two rotations after the Manhattan symmetry."""
    return float(np.mean([np.degrees(np.linalg.norm(log_so3(b @ nearest_symmetric(a, b)[0].T)))
                          for a, b in zip(R_a, R_b)]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1] / ".." / "shared" / "data")
    parser.add_argument("--stride", type=int, default=2)
    args = parser.parse_args()
    rgb_paths = [p for folder in ("icsl_corridor", "icsl_corridor_more")
                 for p in sorted((args.data / folder / "rgb").glob("*.png"))][::args.stride]
    depths = [read_icsl_depth(p.parent.parent / "depth" / p.name, 0.0) for p in rgb_paths]  # as stored
    print(registration(rgb_paths, depths), flush=True)
    print("inverse-depth offset taken off (1/m): parallel planes' angle, perpendicular planes' angle from 90 (deg)")
    for offset in OFFSETS_PER_M:
        parallel, perpendicular = plane_pair_angles(depths, offset)
        print(f"  {offset:.4f}: parallel mean {parallel.mean():.2f} median {np.median(parallel):.2f} ({len(parallel)} "
              f"pairs); perpendicular mean {perpendicular.mean():.2f} median {np.median(perpendicular):.2f} "
              f"({len(perpendicular)})", flush=True)
    corrected = [corrected_icsl_depth(z, ICSL_INVERSE_DEPTH_OFFSET_PER_M) for z in depths]
    R_published = [solve_manhattan(window_normals().estimate(z, ICSL_CORRIDOR_K)).R_cm
                   for z in corrected]
    turned = [i for i, R in enumerate(R_published)
              if abs(np.degrees(np.arctan2(R[0, np.argmax(np.abs(R[2]))], R[2, np.argmax(np.abs(R[2]))]))) > 12]
    print(f"walls' angle from 90 deg in the {len(turned)} frames turned 12+ deg from the corridor (offset taken off), over f")
    for f in FOCALS_PX:
        K = pinhole(f, f * ICSL_CORRIDOR_K[1, 1] / ICSL_CORRIDOR_K[0, 0], ICSL_CORRIDOR_K[0, 2], ICSL_CORRIDOR_K[1, 2])
        angles = [a for a in (wall_angle_deg(corrected[i], K, R_published[i]) for i in turned) if a is not None]
        print(f"  f {f:.1f} px: mean {np.mean(angles):.2f} median {np.median(angles):.2f} ({len(angles)} frames)", flush=True)
    rotations = {WHOLE_PLANE_WINDOW_PX: R_published}
    for window in (w for w in WINDOWS_PX if w != WHOLE_PLANE_WINDOW_PX):
        estimator = window_normals(window)
        rotations[window] = [solve_manhattan(estimator.estimate(z, ICSL_CORRIDOR_K)).R_cm for z in corrected]
    print("mean per-frame angle (deg) between the depth rotations of two plane-fit windows (px), offset taken off")
    print("      " + "".join(f"{w:>6d}" for w in WINDOWS_PX))
    for a in WINDOWS_PX:
        print(f"{a:>6d}" + "".join(f"{mean_angle_deg(rotations[a], rotations[b]):6.2f}" for b in WINDOWS_PX))


if __name__ == "__main__":
    main()
