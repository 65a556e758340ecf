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
- ICL-NUIM kt3: single-frame ARE of the normals alone (as tools/bench_normals.py measures it).

Data: ICSL RGB-D corridor (from LPVO, MIT); ICL-NUIM (Handa et al., ICRA 2014, CC BY 3.0).
Usage: python tools/eval_normals_heldout.py [--model FILE] [--threads 1] [--json OUT]
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
from train_normals import DATA, ICSL_MORE_TRAIN_FRAMES, ICSL_TRAIN_FRAMES, angular_error_deg, icsl_labelled  # noqa: E402

from uareme_fusion import solve_manhattan  # noqa: E402
from uareme_fusion.benchmarks.horizon import icsl_depth_reference, rotation_nees  # noqa: E402
from uareme_fusion.normals.learned import LearnedNormals, LearnedNormalsConfig  # noqa: E402
from uareme_fusion.pipeline.single_image import ImageAnalyser  # noqa: E402

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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default=None, help="model file (default: the shipped weights)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    est = LearnedNormals(model=args.model, config=LearnedNormalsConfig(threads=args.threads))
    analyser = ImageAnalyser(normals=str(est.model_path), cues="normals,lines")
    print(f"model: {est.model_path}")
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
        Path(args.json).write_text(json.dumps(dict(model=str(est.model_path), icsl=icsl, icl_kt3=icl), indent=1))


if __name__ == "__main__":
    main()
