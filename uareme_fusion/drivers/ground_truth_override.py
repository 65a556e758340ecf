"""A source whose ground truth comes from a trajectory file (`eval --gt FILE`), read by
`formats.ground_truth_file` (TUM or EuRoC, gravity-aligned).

    source = with_ground_truth_file(open_source(folder), "groundtruth.txt", time_offset_s=0.0)
"""

from __future__ import annotations

from pathlib import Path

from ..formats.ground_truth_file import read_ground_truth_file
from .base import GroundTruth


def with_ground_truth_file(source, path: str | Path, time_offset_s: float = 0.0):
    """`source`, whose `ground_truth()` now reads `path` (in place of its own); returned for chaining."""
    truth = GroundTruth(*read_ground_truth_file(path, time_offset_s, source.info.R_ci), gravity_aligned=True)
    source.ground_truth = lambda: truth
    return source
