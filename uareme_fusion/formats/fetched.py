"""Real recordings fetched beside the repository (not shipped, not required at run time).

TUM RGB-D `rgbd_dataset_freiburg1_rpy` (CC BY 4.0; 723 RGB frames of a handheld camera turned in roll,
pitch and yaw over an office desk, Kinect depth, mocap ground truth, the Kinect's accelerometer) is
the real RGB-D sequence for training and evaluating the normals. The frames stamped before
`TUM_RPY_EVAL_START_S` (the first 516) are for training; the last 207 are for evaluation only.
Where it lies: `$UAREME_TUM_RPY`, else `../data/rgbd_dataset_freiburg1_rpy` beside the repository.
`tum_rpy_split` writes a split as a TUM folder of its own (links to the images, its rows of each
list), named `rgbd_dataset_freiburg1_rpy_<split>` so that the published freiburg1 intrinsics apply.
"""

from __future__ import annotations

import os
from pathlib import Path

TUM_RPY_EVAL_START_S = 1305031246.7
"""First stamp (s) of the evaluation frames of freiburg1_rpy; frames before it are for training."""
TUM_RPY_FOLDER = "rgbd_dataset_freiburg1_rpy"
_MARGIN_S = {"groundtruth.txt": 0.5, "accelerometer.txt": 0.5}
"""Ground truth and accelerometer rows kept this far past a split's ends (interpolation at its edges)."""


def tum_rpy_root() -> Path | None:
    """The fetched freiburg1_rpy folder, or None when it is not there."""
    env = os.environ.get("UAREME_TUM_RPY")
    root = Path(env) if env else Path(__file__).resolve().parents[2].parent / "data" / TUM_RPY_FOLDER
    return root if (root / "rgb.txt").is_file() else None


def tum_rpy_split(root: str | Path, split: str, out_dir: str | Path) -> Path:
    """Write the `split` ("train" or "eval") of the freiburg1_rpy folder `root` as its own TUM folder
    `out_dir/rgbd_dataset_freiburg1_rpy_<split>` (images linked, not copied) and return it."""
    if split not in ("train", "eval"):
        raise ValueError(f"Expected split 'train' or 'eval', got {split!r}")
    root = Path(root)
    out = Path(out_dir) / f"{TUM_RPY_FOLDER}_{split}"
    for sub in ("rgb", "depth"):
        (out / sub).mkdir(parents=True, exist_ok=True)

    def inside(t: float, margin: float) -> bool:
        return (t >= TUM_RPY_EVAL_START_S - margin) if split == "eval" else (t < TUM_RPY_EVAL_START_S + margin)

    for name in ("rgb.txt", "depth.txt", "groundtruth.txt", "accelerometer.txt"):
        if not (root / name).is_file():
            continue
        kept = []
        for line in (root / name).read_text().splitlines(keepends=True):
            if line.startswith("#") or not line.strip():
                kept.append(line)
                continue
            fields = line.split()
            if not inside(float(fields[0]), _MARGIN_S.get(name, 0.0)):
                continue
            kept.append(line)
            if name in ("rgb.txt", "depth.txt"):
                link = out / fields[1]
                if not link.exists():
                    link.symlink_to((root / fields[1]).resolve())
        (out / name).write_text("".join(kept))
    return out
