"""Held-out real-image figures of a normal network (issue 12 part 3): what decides whether retrained
weights ship.

Held-out frames (never read by tools/train_normals.py): the last 20 of icsl_corridor and the last
40 of icsl_corridor_more (sorted by name; training uses the first `ICSL_TRAIN_FRAMES` and
`ICSL_MORE_TRAIN_FRAMES`), and ICL-NUIM kt3. Prints, for the shipped weights or `--model FILE`:
- ICSL per-pixel normals: the angular error of the learned normals (640x480) against the depth
  normals where those are confident (kappa > 0), median and mean over all such pixels, and the
  median over the pixels in the upper half of the network's kappa;
- ICSL rotations: the RGB-only rotation against the depth-normal rotation of the same frame
  (`benchmarks.horizon.icsl_depth_reference`), after the 24-fold Manhattan symmetry, mean and
  median; once from the normals alone (`solve_manhattan`), once as `image` computes it (normals and
  lines, focal length from the scene; `pipeline.single_image.ImageAnalyser`); the NEES of each;
- ICL-NUIM kt3: single-frame ARE of the normals alone (as tools/bench_normals.py measures it);
- TUM fr1 rpy EVAL frames (the last 207, `--tum`, default the fetched eval split; never trained on):
  the sim-to-real measure of issue 29. The network's normals at 640x480 (from 160x120) against the
  depth normals of the same frame (the TUM driver's undistortion with the published freiburg1
  intrinsics, `DepthNormals`) on every pixel with a confident depth fit (kappa >= 50): mean and
  median over all such pixels, and the mean of the per-frame means;
- `--horizon-figures`: the two no-regression figures of `bench horizon` for this model, computed as
  there (`benchmarks.horizon`): ICSL RGB vs depth rotation, no intrinsics, every 2nd frame of both
  folders (training frames included), cues normals and lines, per image and with K pooled over each
  sequence (issue 29's "ICSL RGB-only <= 1.65"); ICL kt3 RGB-only `eval` ARE mean with
  the single-frame backend (about 3 minutes on a quiet machine; ECD: `bench horizon --ecd-only`).

Data: ICSL RGB-D corridor (from LPVO, MIT); ICL-NUIM (Handa et al., ICRA 2014, CC BY 3.0).
Usage: python tools/eval_normals_heldout.py [--model FILE] [--threads 1] [--json OUT] [--tum-only]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_normals import icl_rotations, kappa_halves  # noqa: E402
from train_normals import (  # noqa: E402
    DATA,
    ICSL_MORE_TRAIN_FRAMES,
    ICSL_TRAIN_FRAMES,
    angular_error_deg,
    icsl_labelled,
    tum_labelled,
)

from uareme_fusion import solve_manhattan  # noqa: E402
from uareme_fusion.formats.fetched import TUM_RPY_FOLDER, tum_rpy_root  # noqa: E402
from uareme_fusion.benchmarks.horizon import icsl_depth_reference, rotation_nees  # noqa: E402
from uareme_fusion.normals.learned import LearnedNormals, LearnedNormalsConfig  # noqa: E402
from uareme_fusion.pipeline.single_image import ImageAnalyser  # noqa: E402


def tum_eval_folder() -> Path | None:
    """The fetched TUM fr1 rpy evaluation split (`formats.fetched.tum_rpy_split`) beside the fetched
    folder (`tum_rpy_root`), or None."""
    root = tum_rpy_root()
    folder = None if root is None else root.parent / f"{TUM_RPY_FOLDER}_eval"
    return folder if folder is not None and (folder / "rgb.txt").is_file() else None

HELDOUT = (("icsl_corridor", ICSL_TRAIN_FRAMES), ("icsl_corridor_more", ICSL_MORE_TRAIN_FRAMES))
"""(folder, first held-out frame index by name): every frame from there on is held out."""


def icsl_heldout(est: LearnedNormals, analyser: ImageAnalyser) -> dict:
    errs, kappas, rows = [], [], []
    for folder, first in HELDOUT:
        rgbs, n_depth, names = icsl_labelled(first, 10_000, (640, 480), folder)
        for rgb, n_true, name in zip(rgbs, n_depth, names):
            path = DATA / folder / "rgb" / name
            nm = est.estimate(rgb)
            valid = np.abs(n_true).sum(-1) > 0.5
            errs.append(angular_error_deg(nm.normals[valid], n_true[valid]))
            kappas.append(nm.kappa[valid])
            ref = icsl_depth_reference(path).R_cm
            alone = solve_manhattan(nm)
            both = analyser.analyse(path).visual
            rows.append((folder, *rotation_nees(alone.R_cm, alone.cov, ref), *rotation_nees(both.R_cm, both.cov, ref)))
    errs, kappas = np.concatenate(errs), np.concatenate(kappas)
    _, upper = kappa_halves(errs, kappas)
    angles = np.array([r[1:] for r in rows])

    def rotation_stats(cols, mask):
        a, n = angles[mask][:, cols[0]], angles[mask][:, cols[1]]
        return dict(mean_deg=float(a.mean()), median_deg=float(np.median(a)), nees_mean=float(n.mean()))

    folders = np.array([r[0] for r in rows])
    out = dict(frames=len(rows), pixel_median_deg=float(np.median(errs)), pixel_mean_deg=float(np.mean(errs)),
               pixel_upper_kappa_median_deg=upper)
    for label, mask in [("all", np.ones(len(rows), bool))] + [(f, folders == f) for f, _ in HELDOUT]:
        out[label] = dict(frames=int(mask.sum()), normals=rotation_stats((0, 1), mask),
                          normals_lines=rotation_stats((2, 3), mask))
    return out


def tum_eval_errors(est: LearnedNormals, root: Path, stride: int = 1) -> dict:
    """Angular error (deg) of the learned normals against confident depth normals on the TUM frames of
    `root` (see the module docstring): pixel mean and median, mean of per-frame means, frames."""
    rgbs, n_depth, _ = tum_labelled(root, size=None, stride=stride)
    errs, frame_means = [], []
    for rgb, n_true in zip(rgbs, n_depth):
        valid = np.abs(n_true).sum(-1) > 0.5
        e = angular_error_deg(est.estimate(rgb).normals[valid], n_true[valid])
        errs.append(e)
        frame_means.append(float(e.mean()))
    errs = np.concatenate(errs)
    return dict(frames=len(rgbs), pixels=int(errs.size), pixel_mean_deg=float(errs.mean()),
                pixel_median_deg=float(np.median(errs)), frame_mean_deg=float(np.mean(frame_means)))


def horizon_figures(model: Path | None, cues: str = "normals,lines") -> dict:
    """ICSL mean rotation error and ICL kt3 ARE mean of `bench horizon` with the network `model` (None: the
    shipped one, as `bench horizon` runs it; a file runs there as a drop-in does, without the mirror average:
    copy it over the shipped weights to judge it as it would ship)."""
    import tempfile

    from uareme_fusion.benchmarks.horizon import icsl_scores, pooled_scores
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.session import run_to_folder

    folders = [DATA / "icsl_corridor", DATA / "icsl_corridor_more"]
    normals = "learned" if model is None else str(model)
    analyser = ImageAnalyser(normals=normals, cues=cues)
    icsl = icsl_scores(folders, analyser, stride=2)
    pooled = pooled_scores(folders, analyser, stride=2)
    with tempfile.TemporaryDirectory() as out:
        kt3 = run_to_folder(str(DATA / "icl_nuim_office_kt3"), out,
                            RunConfig(backend="single", normals=normals, cues=cues), evaluate=True,
                            command="eval_normals_heldout")
    return dict(icsl_mean_deg=icsl["mean_angle_deg"], icsl_median_deg=icsl["median_angle_deg"],
                icsl_nees_mean=icsl["nees_mean"], icsl_frames=icsl["frames"],
                icsl_pooled_mean_deg=pooled["mean_angle_deg"], icsl_pooled_median_deg=pooled["median_angle_deg"],
                kt3_are_mean_deg=kt3["are_deg"]["mean"], kt3_nees_mean=kt3["nees"]["mean"])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default=None, help="model file (default: the shipped weights)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
    parser.add_argument("--tum", default=None, help="TUM evaluation folder (default: the fetched eval split)")
    parser.add_argument("--tum-only", action="store_true", help="only the TUM evaluation figures")
    parser.add_argument("--horizon-figures", action="store_true", help="only the ICSL and kt3 figures of bench "
                        "horizon for this model")
    args = parser.parse_args(argv)
    if args.horizon_figures:
        figures = horizon_figures(Path(args.model) if args.model else None)
        print(f"bench horizon figures: ICSL RGB vs depth rotation, no intrinsics, mean ({figures['icsl_frames']} "
              f"frames) {figures['icsl_mean_deg']:.3f} deg, median {figures['icsl_median_deg']:.3f}, NEES mean "
              f"{figures['icsl_nees_mean']:.2f}; K pooled over each sequence: mean "
              f"{figures['icsl_pooled_mean_deg']:.3f} deg, median {figures['icsl_pooled_median_deg']:.3f}; "
              f"ICL kt3 RGB-only ARE mean {figures['kt3_are_mean_deg']:.3f} deg, "
              f"NEES mean {figures['kt3_nees_mean']:.2f}")
        if args.json:
            Path(args.json).write_text(json.dumps(figures, indent=1))
        return
    est = LearnedNormals(model=args.model, config=LearnedNormalsConfig(threads=args.threads, mirror_average=True))
    print(f"model: {est.model_path}")
    tum, tum_folder = None, Path(args.tum) if args.tum else tum_eval_folder()
    if tum_folder is not None:
        tum = tum_eval_errors(est, tum_folder)
        print(f"TUM eval ({tum['frames']} frames of {tum_folder}, never trained on), learned vs depth normals where "
              f"depth kappa >= 50 ({tum['pixels']} pixels): mean {tum['pixel_mean_deg']:.2f} deg, median "
              f"{tum['pixel_median_deg']:.2f}, mean of frame means {tum['frame_mean_deg']:.2f}")
    if args.tum_only:
        if args.json:
            Path(args.json).write_text(json.dumps(dict(model=str(est.model_path), tum_eval=tum), indent=1))
        return
    analyser = ImageAnalyser(normals=str(est.model_path), cues="normals,lines")
    icsl = icsl_heldout(est, analyser)
    print(f"ICSL held-out ({icsl['frames']} frames: {', '.join(f'{f} from #{i}' for f, i in HELDOUT)}), "
          f"learned vs depth normals where depth kappa > 0: median {icsl['pixel_median_deg']:.2f} deg, mean "
          f"{icsl['pixel_mean_deg']:.2f}, upper-kappa-half median {icsl['pixel_upper_kappa_median_deg']:.2f}")
    for label in ("all",) + tuple(f for f, _ in HELDOUT):
        row = icsl[label]
        for cues in ("normals", "normals_lines"):
            r = row[cues]
            print(f"  {label} ({row['frames']} frames) RGB-only rotation vs depth rotation, cues {cues}: mean "
                  f"{r['mean_deg']:.2f} deg, median {r['median_deg']:.2f}, NEES mean {r['nees_mean']:.2f}")
    root = DATA / "icl_nuim_office_kt3"
    icl = icl_rotations(lambda i: est.estimate(cv2.imread(str(root / "rgb" / f"{i}.png"), cv2.IMREAD_COLOR)[..., ::-1]))
    if icl is not None:
        print(f"ICL-NUIM kt3 single-frame ARE from learned normals alone ({icl['frames']} frames): mean "
              f"{icl['are_mean_deg']:.2f} deg, median {icl['are_median_deg']:.2f}, max {icl['are_max_deg']:.2f}; "
              f"NEES mean {icl['nees_mean']:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(dict(model=str(est.model_path), icsl=icsl, icl_kt3=icl, tum_eval=tum),
                                              indent=1))


if __name__ == "__main__":
    main()
