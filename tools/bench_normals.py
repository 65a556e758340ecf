"""Benchmark of the learned normals (issue 4's numbers) and of the depth normals beside them.

Prints, for the shipped weights or `--model FILE`:
- held-out synthetic views (simulator scenes from seeds never used in training, 320x240): median
  angular error of the normals (goal <= 15 deg); kappa informativeness: median error of the pixels
  in the upper half of kappa against the lower half (goal: lower by >= 1.5x); single-frame rotation
  error and the NEES of the solver's covariance (goal: mean ~3), with the `independent_regions`
  that would make the mean NEES exactly 3;
- ICSL corridor, its last 20 frames (never trained on): median angular error against depth
  normals where those are confident (goal <= 25 deg);
- ICL-NUIM office kt3 (never trained on): single-frame ARE mean/median/max from learned normals
  (goal: mean <= 6 deg) and from depth normals (goal: mean <= 2 deg), each solve initialised from
  the previous frame (`SingleFrame`), after one constant alignment; NEES of the covariances;
- timings (median of `--repeats`): learned normals per frame at the 320x240 internal size (goal
  <= 40 ms on a 2-core CPU), depth normals per 640x480 frame (goal <= 10 ms). Timings on a shared
  machine are noisy.

Data: ICL-NUIM (Handa et al., ICRA 2014, CC BY 3.0); ICSL RGB-D corridor (from LPVO, MIT).
Usage: python tools/bench_normals.py [--model FILE] [--repeats 30] [--views 6] [--threads 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from train_normals import HELDOUT_SEED0, SCENES, angular_error_deg, icsl_labelled, render_views  # noqa: E402

from uareme_fusion import solve_manhattan  # noqa: E402
from uareme_fusion.backends.single import SingleFrame  # noqa: E402
from uareme_fusion.normals.depth import (  # noqa: E402
    ICL_NUIM_DEPTH_UNIT_M,
    ICL_NUIM_K_OPENCV,
    DepthNormals,
    flip_y_rotation,
    read_depth_png,
)
from uareme_fusion.normals.learned import LearnedNormals, LearnedNormalsConfig  # noqa: E402
from uareme_fusion.rotations import align_constant, angle_between, are_deg, matrix_from_quat_xyzw, nearest_symmetric, nees  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SIZE = (320, 240)
"""Size of the rendered held-out views and of the timing images."""
CHI2_3_MEDIAN = 2.366
"""Median of the chi-square distribution with 3 degrees of freedom (what a consistent NEES has)."""


def kappa_halves(errors_deg: np.ndarray, kappa: np.ndarray) -> tuple[float, float]:
    """(median error of the lower half of pixels ranked by kappa, of the upper half)."""
    order = np.argsort(kappa, kind="stable")
    half = len(order) // 2
    return float(np.median(errors_deg[order[:half]])), float(np.median(errors_deg[order[half:]]))


def synthetic_heldout(est: LearnedNormals, seeds: int, views: int) -> dict:
    errs, kappas, raw_kappas, rot_err, nees_values = [], [], [], [], []
    for k, scene in enumerate(SCENES):
        for s in range(seeds):
            seed = HELDOUT_SEED0 + s
            rgbs, normals, R_cms = render_views(scene, seed, views, *SIZE, np.random.default_rng([seed, k, 1]))
            for rgb, n_true, R_cm in zip(rgbs, normals, R_cms):
                raw = est.infer(rgb)
                nm = est.to_normal_map(raw, rgb.shape[:2])
                valid = np.abs(n_true).sum(-1) > 0.5
                errs.append(angular_error_deg(nm.normals[valid], n_true[valid]))
                kappas.append(nm.kappa[valid])
                raw_kappas.append(cv2.resize(raw[3], SIZE, interpolation=cv2.INTER_LINEAR)[valid])
                visual = solve_manhattan(nm)
                R_est, _ = nearest_symmetric(visual.R_cm, R_cm)
                rot_err.append(float(np.degrees(angle_between(R_est, R_cm))))
                nees_values.append(float(nees(R_est, R_cm, visual.cov)))
    errs, kappas, raw_kappas = map(np.concatenate, (errs, kappas, raw_kappas))
    lo, hi = kappa_halves(errs, kappas)
    raw_lo, raw_hi = kappa_halves(errs, raw_kappas)
    nees_values = np.array(nees_values)
    ir = est.config.independent_regions
    return dict(frames=len(rot_err), median_deg=float(np.median(errs)), mean_deg=float(np.mean(errs)),
                kappa_low_half_deg=lo, kappa_high_half_deg=hi, kappa_ratio=lo / hi,
                raw_kappa_ratio=raw_lo / raw_hi, kappa_at_cap=float(np.mean(kappas >= est.config.kappa_cap)),
                rotation_median_deg=float(np.median(rot_err)), rotation_mean_deg=float(np.mean(rot_err)),
                nees_mean=float(nees_values.mean()), nees_median=float(np.median(nees_values)),
                independent_regions=ir, independent_regions_for_nees3=ir * 3.0 / float(nees_values.mean()),
                independent_regions_for_median=ir * CHI2_3_MEDIAN / float(np.median(nees_values)))


def icsl_last20(est: LearnedNormals) -> dict | None:
    if not (DATA / "icsl_corridor").is_dir():
        return None
    rgbs, n_depth, names = icsl_labelled(first=60, count=20, size=(640, 480))
    errs, kappas = [], []
    for rgb, n_true in zip(rgbs, n_depth):
        nm = est.estimate(rgb)
        valid = np.abs(n_true).sum(-1) > 0.5
        errs.append(angular_error_deg(nm.normals[valid], n_true[valid]))
        kappas.append(nm.kappa[valid])
    errs, kappas = np.concatenate(errs), np.concatenate(kappas)
    lo, hi = kappa_halves(errs, kappas)
    return dict(frames=f"{names[0]} .. {names[-1]}", median_deg=float(np.median(errs)), kappa_ratio=lo / hi)


def icl_rotations(normal_map_of) -> dict | None:
    """Single-frame ARE on ICL-NUIM kt3 from `normal_map_of(index) -> NormalMap`."""
    root = DATA / "icl_nuim_office_kt3"
    if not (root / "groundtruth.txt").is_file():
        return None
    gt = np.loadtxt(root / "groundtruth.txt")
    gt = gt[[(root / "rgb" / f"{int(i)}.png").is_file() for i in gt[:, 0]]]
    R_gt = flip_y_rotation(matrix_from_quat_xyzw(gt[:, 4:8]))
    backend = SingleFrame()
    R_est, covs = [], []
    for i in gt[:, 0].astype(int):
        visual = solve_manhattan(normal_map_of(i), R_init=backend.predicted_R_cm(float(i)))
        e = backend.process_frame(float(i), visual)
        R_est.append(e.R_wc)
        covs.append(e.cov)
    R_est = np.array(R_est)
    are = are_deg(R_est, R_gt)
    A = align_constant(R_est, R_gt)
    return dict(frames=len(are), are_mean_deg=float(are.mean()), are_median_deg=float(np.median(are)),
                are_max_deg=float(are.max()), nees_mean=float(nees(A @ R_est, R_gt, np.array(covs)).mean()))


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default=None, help="model file (default: the shipped weights)")
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=2, help="held-out scenes per scene type")
    parser.add_argument("--views", type=int, default=6, help="views per held-out scene")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--independent-regions", type=float, default=None)
    args = parser.parse_args(argv)
    regions = {} if args.independent_regions is None else {"independent_regions": args.independent_regions}
    cfg = LearnedNormalsConfig(threads=args.threads, mirror_average=True, **regions)
    est = LearnedNormals(model=args.model, config=cfg)
    size = f"{cfg.width_px}x{cfg.height_px}"
    print(f"model: {est.model_path}, internal size {size}")

    syn = synthetic_heldout(est, args.seeds, args.views)
    print(f"held-out synthetic ({syn['frames']} views of {', '.join(SCENES)} rendered at 320x240):")
    print(f"  median angular error {syn['median_deg']:.2f} deg (goal <= 15), mean {syn['mean_deg']:.2f}")
    print(f"  kappa: lower half median {syn['kappa_low_half_deg']:.2f} deg, upper half "
          f"{syn['kappa_high_half_deg']:.2f} deg, ratio {syn['kappa_ratio']:.2f} (goal >= 1.5; uncapped kappa "
          f"{syn['raw_kappa_ratio']:.2f}; {100 * syn['kappa_at_cap']:.0f}% of pixels at the cap)")
    print(f"  single-frame rotation error median {syn['rotation_median_deg']:.2f} deg, mean "
          f"{syn['rotation_mean_deg']:.2f}; NEES mean {syn['nees_mean']:.2f} (goal ~3), median "
          f"{syn['nees_median']:.2f} (chi2(3) median {CHI2_3_MEDIAN}); independent_regions "
          f"{syn['independent_regions']:g} (mean NEES 3 at {syn['independent_regions_for_nees3']:.2f}, median "
          f"NEES {CHI2_3_MEDIAN} at {syn['independent_regions_for_median']:.2f})")

    icsl = icsl_last20(est)
    if icsl is None:
        print("ICSL corridor: data not found, skipped")
    else:
        print(f"ICSL corridor last 20 frames ({icsl['frames']}), vs depth normals: median angular error "
              f"{icsl['median_deg']:.2f} deg (goal <= 25); kappa ratio {icsl['kappa_ratio']:.2f}")

    root = DATA / "icl_nuim_office_kt3"

    def learned_map(i):
        rgb = cv2.imread(str(root / "rgb" / f"{i}.png"), cv2.IMREAD_COLOR)[..., ::-1]
        return est.estimate(rgb)

    depth_est = DepthNormals()

    def depth_map(i):
        depth = read_depth_png(root / "depth" / f"{i}.png", ICL_NUIM_DEPTH_UNIT_M, (480, 640))
        return depth_est.estimate(depth, ICL_NUIM_K_OPENCV)

    for name, fn, goal in (("learned", learned_map, 6.0), ("depth", depth_map, 2.0)):
        icl = icl_rotations(fn)
        if icl is None:
            print("ICL-NUIM kt3: data not found, skipped")
            break
        print(f"ICL-NUIM kt3 single-frame ARE from {name} normals ({icl['frames']} frames): mean "
              f"{icl['are_mean_deg']:.2f} deg (goal <= {goal:g}), median {icl['are_median_deg']:.2f}, max "
              f"{icl['are_max_deg']:.2f}; NEES mean {icl['nees_mean']:.2f}")

    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    est_320 = LearnedNormals(model=args.model, config=LearnedNormalsConfig(threads=args.threads, width_px=320,
                                                                           height_px=240))
    ms_320 = median_ms(lambda: est_320.estimate(rgb), args.repeats)
    rgb_vga = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    ms_vga = median_ms(lambda: est.estimate(rgb_vga), args.repeats)
    depth = (1.0 + rng.random((480, 640))).astype(np.float32)
    ms_depth = median_ms(lambda: depth_est.estimate(depth, ICL_NUIM_K_OPENCV), args.repeats)
    print(f"timing (median of {args.repeats}, {args.threads} torch threads, shared machine: noisy): learned "
          f"normals {ms_320:.1f} ms per frame at a 320x240 internal size (goal <= 40); {ms_vga:.1f} ms per "
          f"640x480 frame at the {size} internal size (resizing both ways included); depth normals "
          f"{ms_depth:.1f} ms per 640x480 frame (goal <= 10)")


if __name__ == "__main__":
    main()
