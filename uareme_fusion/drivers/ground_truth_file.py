"""Ground truth from a trajectory file attached to a source, for `eval --gt FILE` on sources without
their own:

    source = with_ground_truth_file(open_source(folder), "groundtruth.txt", time_offset_s=0.0)

The file's formats, frames and the time-offset convention are those of `formats.ground_truth`, which
reads it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..formats.ground_truth import read_ground_truth_file
from ..errors import InputError
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
