"""ICL-NUIM sequences (Handa et al., ICRA 2014) as a `Source`, in OpenCV camera axes.

Layout: `rgb/N.png`, `depth/N.png` (uint16, 1/5000 m), `associations.txt` (`t depth/N.png t rgb/N.png`)
and `groundtruth.txt` (TUM format), where the timestamps t are frame numbers. We yield
`t = N / fps` seconds (`fps` 30 by default, the rendering rate) and scale the ground truth's times
the same way.

The published intrinsics have fy = -480 (a y-up camera frame). Frames carry
`ICL_NUIM_K_OPENCV` (fy = +480, the same pixels in the OpenCV y-down frame) and the ground truth
is converted with `flip_y_rotation`: `R_wc = FLIP_Y R_wc' FLIP_Y`, camera OpenCV axes to the
dataset's world mirrored in y, which is not gravity aligned (evaluation aligns a constant rotation).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.formats.datasets import flip_y_rotation

from .base import GroundTruth
from .intrinsics import PUBLISHED, CameraModel
from .tum import TumSource, ground_truth_from_tum

ICL_NUIM_FPS = 30.0


class IclNuimSource(TumSource):
    """An ICL-NUIM folder (needs `associations.txt`); see the module docstring."""

    def __init__(self, root: str | Path, fps: float | None = None, max_dt_s: float = 0.5):
        fps = ICL_NUIM_FPS if fps is None else fps
        if not (np.isfinite(fps) and fps > 0):
            raise InputError(f"--fps must be > 0, got {fps}")
        root = Path(root)
        if root.is_dir() and not (root / "associations.txt").is_file():
            raise InputError(f"ICL-NUIM folder {root}: associations.txt is missing")
        self.time_scale = 1.0 / fps
        super().__init__(root, use_imu=False, use_normals=False, max_dt_s=max_dt_s)

    def _camera(self) -> CameraModel:
        return dataclasses.replace(PUBLISHED["ICL-NUIM"], origin="published ICL-NUIM intrinsics")

    def ground_truth(self) -> GroundTruth | None:
        if self.seq.groundtruth is None:
            return None
        return ground_truth_from_tum(self.seq.groundtruth, False, self.time_scale, R_fix=flip_y_rotation)
