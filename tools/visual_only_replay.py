"""The visual-only backends against `single` on every real development sequence, from cached rotations.

`bench realdata` solves each sequence's cue sets once, then runs `single`, `mekf` and `smoother` on the
same per-frame rotations. This tool does the solving once into a cache (`--build`), then replays the
backends without an IMU (EuRoC's IMU is dropped: the camera alone) in seconds, printing per sequence and
cue set the ARE of the image rotations between frames alone (visual odometry, chained from the first frame),
and each backend's ARE beside `single`'s with the paired 95 % interval (`bench realdata`'s figures).

Usage:
  python tools/visual_only_replay.py --build --cache /tmp/visual_only.pkl [--data ../shared/data] [--tum-split train]
  python tools/visual_only_replay.py --cache /tmp/visual_only.pkl [MORE.pkl ...] [--only tum,icsl_more]
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
import tempfile
from pathlib import Path

import numpy as np


def build(data: Path, cache: Path, wanted, tum_split: str = "eval") -> None:
    from uareme_fusion.benchmarks import realdata
    from uareme_fusion.formats.fetched import tum_rpy_root, tum_rpy_split

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = tum_rpy_root()
        tum_dir = tum_rpy_split(root, tum_split, Path(tmp)) if root is not None else None
        found, skipped = realdata.sequences(data, tum_dir, wanted)
        print("\n".join(skipped))
        for seq in found:
            for cue, (normals, cues) in realdata.CUE_SETS.items():
                if normals == "depth" and not seq.has_depth:
                    continue
                visual, info, _ = realdata.cue_set_sequence(seq, normals, cues, None, lambda *a: None)
                visual = dataclasses.replace(visual, imu_t_s=None, imu_gyro_rad_s=None, imu_accel_m_s2=None)
                name = seq.name if tum_split == "eval" or seq.key != "tum" else seq.name.replace("eval", tum_split)
                out[(name, cue)] = (visual, info)
                print(f"{name}: {cue}: {len(visual.t_frame_s)} frames", flush=True)
                with open(cache, "wb") as f:
                    pickle.dump(out, f)


def image_rotations_are_deg(visual) -> float:
    """Mean ARE (deg, after the constant alignment) of the image rotations between frames alone
    (`VisualRotation.R_cp`, chained from the first frame; a frame without one keeps the previous attitude):
    what the frames' absolute rotations add to, or take from, the visual odometry."""
    from uareme_fusion.rotations import are_deg

    R_wc = [np.eye(3)]
    for v in visual.visuals[1:]:
        R_wc.append(R_wc[-1] if v is None or v.R_cp is None else R_wc[-1] @ v.R_cp.T)  # R_wc = R_wc_p R_cp^T
    return float(np.mean(are_deg(np.array(R_wc), visual.R_wc_true)))


def replay(caches: list[Path], only: list[str] | None, mekf: dict | None = None, smoother: dict | None = None) -> dict:
    from uareme_fusion.benchmarks import realdata
    from uareme_fusion.evaluation.paired_difference import paired_difference

    sequences = {}
    for path in caches:
        with open(path, "rb") as f:
            sequences.update(pickle.load(f))
    table = {}
    for (name, cue), (visual, info) in sequences.items():
        if only and not any(o.lower() in name.lower() for o in only):
            continue
        errs = realdata.backend_errors(visual, info, realdata.CUE_SETS[cue][0], mekf, smoother)
        single = errs["single"]["are_deg"]
        line = (f"{name:20s} {cue:18s} image rotations alone {image_rotations_are_deg(visual):6.2f} | "
                f"single {np.nanmean(single):6.2f} NEES {np.nanmean(errs['single']['nees']):6.2f}")
        for b in ("mekf", "smoother"):
            d = paired_difference(errs[b]["are_deg"], single)
            table[(name, cue, b)] = (float(np.nanmean(errs[b]["are_deg"])), d)
            line += (f" | {b} {np.nanmean(errs[b]['are_deg']):6.2f} NEES {np.nanmean(errs[b]['nees']):6.2f} "
                     f"{d['mean']:+6.2f} ({d['low']:+6.2f} .. {d['high']:+6.2f}){' WORSE' if d['low'] > 0 else ''}")
        print(line, flush=True)
    return table


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cache", type=Path, nargs="+", required=True)
    p.add_argument("--build", action="store_true")
    p.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1] / ".." / "shared" / "data")
    p.add_argument("--tum-split", choices=("eval", "train"), default="eval",
                   help="--build: the TUM fr1 rpy frames to solve (train: for tuning; eval: never tuned on)")
    p.add_argument("--only", default=None, help="comma-separated sequence keys")
    p.add_argument("--mekf", nargs="*", default=[], help="MekfConfig overrides KEY=VALUE")
    p.add_argument("--smoother", nargs="*", default=[], help="SmootherConfig overrides KEY=VALUE")
    a = p.parse_args()
    only = a.only.split(",") if a.only else None
    if a.build:
        from uareme_fusion.benchmarks.realdata import SEQUENCES
        build(a.data, a.cache[0], SEQUENCES if only is None else only, a.tum_split)
    else:
        replay(a.cache, only, dict(kv.split("=", 1) for kv in a.mekf), dict(kv.split("=", 1) for kv in a.smoother))


if __name__ == "__main__":
    main()
