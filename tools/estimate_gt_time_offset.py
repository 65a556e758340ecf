"""The ground-truth clock offset of a TUM RGB-D folder, from a depth-normal run (how
`formats.tum.TUM_RGBD_GT_TIME_OFFSET_S` was measured, on the fr1 rpy TRAIN frames only).

    D=/work/data/rgbd_dataset_freiburg1_rpy_train
    uareme-fusion eval $D --normals depth --backend single --gt-time-offset-s 0 --out /tmp/train_run
    python tools/estimate_gt_time_offset.py /tmp/train_run $D

Prints the offset (s added to groundtruth.txt's stamps, `evaluation.time_offset.estimate_time_offset`)
over the frames with a depth image (as the driver pairs them) and over each half (a check that it is
one constant, not drift), the mean ARE at 0 and
at the offset, and the ARE curve every 10 ms. With `--depth-stamps` each estimate is timed at its depth
image's stamp (`depth.txt`) instead of the rgb image's.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.drivers.tum import TumSource
from uareme_fusion.evaluation.time_offset import estimate_time_offset
from uareme_fusion.formats.tum import associate, read_tum_list, read_tum_trajectory


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", type=Path, help="the --out folder of an eval run with --gt-time-offset-s 0")
    parser.add_argument("folder", type=Path, help="the TUM RGB-D folder that run read")
    parser.add_argument("--depth-stamps", action="store_true", help="time each estimate at its depth image")
    args = parser.parse_args(argv)
    t_s, _, quat = read_tum_trajectory(args.run_dir / "trajectory.tum")
    R_wc = Rotation.from_quat(quat).as_matrix()
    t_depth, _ = read_tum_list(args.folder / "depth.txt")
    i_rgb, i_depth = associate(t_s, t_depth, 0.02)  # as the TUM driver pairs them: frames without depth left out
    t_s, R_wc = (t_depth[i_depth] if args.depth_stamps else t_s[i_rgb]), R_wc[i_rgb]
    with TumSource(args.folder) as source:
        truth = source.ground_truth()
        truth = dataclasses.replace(truth, t_s=truth.t_s - source.info.gt_time_offset_s)  # the file's own stamps
    n = len(t_s)
    for part, sel in (("all frames", slice(None)), ("first half", slice(0, n // 2)), ("second half", slice(n // 2, None))):
        est = estimate_time_offset(t_s[sel], R_wc[sel], truth)
        print(f"{part}: offset {est.offset_s * 1000:+.1f} ms (95 % {est.low_s * 1000:+.1f} .. {est.high_s * 1000:+.1f}) "
              f"over {est.frames} frames, "
              f"mean ARE {est.are_deg_at_zero:.3f} at 0 -> {est.are_deg_at_offset:.3f} deg")
        if part == "all frames":
            curve = est
    for d in np.arange(-60, 61, 10):
        k = int(np.argmin(np.abs(curve.offsets_s * 1000 - d)))
        print(f"  {d:+4d} ms: mean ARE {curve.mean_are_deg[k]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
