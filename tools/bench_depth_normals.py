"""Benchmark of DepthNormals: ms/frame at 640x480 and single-frame rotation accuracy on ICL-NUIM.

Prints (median over repeats; timings are noisy on a shared machine):
- DepthNormals time per 640x480 frame, every pixel fitted (stride 1) and every other one (stride 2);
- ICL-NUIM office kt3 (frames 1..100): ARE mean/median/max of single-frame rotations from depth
  normals (each solve initialised from the previous frame), the NEES of the solver's covariance
  after the constant alignment, and the solver's time;
- ICSL corridor: valid-normal fraction, solver quality and frame-to-frame rotation.

Data: ICL-NUIM (Handa et al., ICRA 2014, CC BY 3.0); ICSL RGB-D corridor (from LPVO, MIT).
Usage: python tools/bench_depth_normals.py [--repeats 30] [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from uareme_fusion import solve_manhattan
from uareme_fusion.backends.single import SingleFrame
from uareme_fusion.normals.depth import (
    ICL_NUIM_DEPTH_UNIT_M,
    ICL_NUIM_K_OPENCV,
    ICSL_CORRIDOR_K,
    MILLIMETRE_DEPTH_UNIT_M,
    DepthNormals,
    DepthNormalsConfig,
    flip_y_rotation,
    read_depth_png,
)
from uareme_fusion.rotations import align_constant, angle_between, are_deg, matrix_from_quat_xyzw, nees

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def median_ms(fn, repeats: int, keep_result: bool) -> float:
    """Median wall time of fn(). keep_result=True holds each result until the next call returns, as
    a frame loop does; False drops it at once, so glibc gives the ~40 MB of freed temporaries back to
    the OS and every call page-faults them in again (about twice as slow: a property of the
    allocator, not of the maths; MALLOC_TRIM_THRESHOLD_ set large removes it)."""
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        new = fn()
        times.append(time.perf_counter() - t0)
        result = new if keep_result else None
        del new
    del result
    return 1e3 * float(np.median(times))


def sequence_rotations(depth_files, K, unit_m, estimator: DepthNormals):
    """R_wc (N, 3, 3) and its right-perturbation covariance (N, 3, 3) per frame, the SingleFrame way
    (R_wc = R_cm^T, labelling nearest the previous frame), plus solver quality, solver ms and
    DepthNormals ms per frame."""
    backend = SingleFrame()
    estimates, quality, solve_ms, normals_ms = [], [], [], []
    for k, path in enumerate(depth_files):
        depth = read_depth_png(path, unit_m, (480, 640))
        t0 = time.perf_counter()
        nm = estimator.estimate(depth, K, source=str(path))
        normals_ms.append(1e3 * (time.perf_counter() - t0))
        visual = solve_manhattan(nm, R_init=backend.predicted_R_cm(float(k)))
        estimates.append(backend.process_frame(float(k), visual))
        quality.append(visual.quality)
        solve_ms.append(sum(visual.timing_ms.values()))
    R_wc = np.array([e.R_wc for e in estimates])
    cov = np.array([e.cov for e in estimates])
    return R_wc, cov, np.array(quality), np.array(solve_ms), np.array(normals_ms)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()

    icl = args.data / "icl_nuim_office_kt3"
    K_cv = ICL_NUIM_K_OPENCV  # ICL publishes fy = -480 (camera y up); OpenCV's y is down
    if (icl / "depth" / "10.png").is_file():
        depth = read_depth_png(icl / "depth" / "10.png", ICL_NUIM_DEPTH_UNIT_M, (480, 640))
    else:  # a tilted plane, so the timing runs without the data
        v, u = np.mgrid[0:480, 0:640].astype(np.float32)
        depth = 2.0 / (1.0 + 0.3 * (u - 320) / 481 + 0.2 * (v - 240) / 480)
    print("DepthNormals at 640x480 (median of %d, float32, shared 2-core CPU: noisy)" % args.repeats)
    for stride in (1, 2):
        est = DepthNormals(DepthNormalsConfig(stride_px=stride))
        est.estimate(depth, K_cv)
        loop = median_ms(lambda: est.estimate(depth, K_cv), args.repeats, keep_result=True)
        dropped = median_ms(lambda: est.estimate(depth, K_cv), args.repeats, keep_result=False)
        print(
            f"  stride {stride}{' (default)' if stride == DepthNormalsConfig().stride_px else ''}: "
            f"{loop:6.2f} ms/frame in a frame loop ({loop / 10:.2f}x the 10 ms budget); "
            f"{dropped:6.2f} ms when each result is dropped at once"
        )

    if not (icl / "groundtruth.txt").is_file():
        print(f"ICL-NUIM not found under {icl}: rotation check skipped")
    else:
        gt = np.loadtxt(icl / "groundtruth.txt")
        gt = gt[[(icl / "depth" / f"{int(i)}.png").is_file() for i in gt[:, 0]]]
        files = [icl / "depth" / f"{int(i)}.png" for i in gt[:, 0]]
        R_wc_gt = flip_y_rotation(matrix_from_quat_xyzw(gt[:, 4:8]))  # into the OpenCV camera frame
        for stride in (1, 2):
            est = DepthNormals(DepthNormalsConfig(stride_px=stride))
            R_wc, cov, _, solve_ms, normals_ms = sequence_rotations(files, K_cv, ICL_NUIM_DEPTH_UNIT_M, est)
            are = are_deg(R_wc, R_wc_gt)
            A = align_constant(R_wc, R_wc_gt)
            e = nees(A @ R_wc, R_wc_gt, cov)
            print(
                f"ICL-NUIM office kt3, {len(files)} frames, depth normals stride {stride}: ARE mean "
                f"{are.mean():.3f} median {np.median(are):.3f} max {are.max():.3f} deg (target mean <= 2)"
            )
            print(
                f"  solver covariance NEES mean {e.mean():.3f} median {np.median(e):.3f} (3 = calibrated); "
                f"in this loop DepthNormals {np.median(normals_ms):.2f} and solver "
                f"{np.median(solve_ms):.2f} ms/frame (median)"
            )

    corridor = sorted((args.data / "icsl_corridor" / "depth").glob("*.png"))
    if corridor:
        est = DepthNormals()
        valid = np.mean([np.mean(est.estimate(read_depth_png(f, MILLIMETRE_DEPTH_UNIT_M), ICSL_CORRIDOR_K).kappa > 0)
                         for f in corridor[::10]])
        R_wc, _, quality, _, _ = sequence_rotations(corridor, ICSL_CORRIDOR_K, MILLIMETRE_DEPTH_UNIT_M, est)
        steps = np.degrees(angle_between(R_wc[:-1], R_wc[1:]))
        print(
            f"ICSL corridor, {len(corridor)} frames (mm depth): valid normals {valid:.1%}, solver quality "
            f"mean {quality.mean():.3f}, frame-to-frame rotation mean {steps.mean():.2f} max {steps.max():.2f} deg"
        )


if __name__ == "__main__":
    main()
