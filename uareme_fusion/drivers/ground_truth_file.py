"""Ground truth from a trajectory file, for `eval --gt FILE` on sources without their own.

    source = with_ground_truth_file(open_source(folder), "groundtruth.txt", time_offset_s=0.0)

Formats (told apart by the first data line: commas mean EuRoC):
- TUM (`timestamp tx ty tz qx qy qz qw`, seconds, whitespace): the camera's `R_wc`;
- EuRoC ground truth (`timestamp [ns], p xyz, q_RS w x y z, ...`, commas): the body (IMU) frame's
  `R_wi`, turned into the camera's `R_wc = R_wi R_ci^T` with the run's camera-IMU rotation.
Both worlds are taken as gravity-aligned (z up), as in EuRoC, TUM RGB-D with its IMU and our own
outputs; `time_offset_s` is added to the file's stamps to put them on the source's clock (the same
convention as `--imu-time-offset-s`). The file is read by `formats.ground_truth`.
"""

from __future__ import annotations

from pathlib import Path

from ..formats.ground_truth import read_ground_truth_file
from .base import GroundTruth


def with_ground_truth_time_offset(source, time_offset_s: float):
    """`source`, whose own ground truth's stamps are shifted by `time_offset_s` in place of the source's
    default (`info.gt_time_offset_s`: TUM RGB-D's, 0 elsewhere), with a note; returned for chaining."""
    if not np.isfinite(time_offset_s):
        raise InputError(f"--gt-time-offset-s must be a finite number of seconds, got {time_offset_s}")
    own, default = source.ground_truth, source.info.gt_time_offset_s

    def shifted():
        truth = own()
        return None if truth is None else dataclasses.replace(truth, t_s=truth.t_s + time_offset_s - default)

    source.ground_truth = shifted
    source.info = dataclasses.replace(source.info, gt_time_offset_s=float(time_offset_s))
    if isinstance(getattr(source, "notes", None), list):
        source.notes.append(f"--gt-time-offset-s: ground-truth stamps {time_offset_s * 1000:+.0f} ms onto the "
                            f"camera's clock, in place of the source's {default * 1000:+.0f} ms")
    return source


def with_ground_truth_file(source, path: str | Path, time_offset_s: float = 0.0):
    """`source`, whose `ground_truth()` now reads `path` (in place of its own); returned for chaining."""
    truth = GroundTruth(*read_ground_truth_file(path, time_offset_s, source.info.R_ci), gravity_aligned=True)
    source.ground_truth = lambda: truth
    return source
