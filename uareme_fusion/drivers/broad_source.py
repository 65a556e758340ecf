"""A BROAD trial (HDF5) as an IMU-only source with its optical reference as ground truth.

    with BroadSource("07_undisturbed_fast_rotation_B.hdf5") as src: ...

Built on `broad.read_broad`. Yields batches of `IMU_ONLY_BATCH_S` (one estimate each); times are
`sample index / sampling_rate`. The "camera" is the IMU itself (`R_ci` identity), so the ground
truth `R_wc` is BROAD's `opt_quat` as `R_wi`: IMU to the ENU reference (z up, gravity aligned), on
the samples where the optical system saw the markers (`n_reference_missing` counts the others).
`movement` (samples to score, as in the BROAD paper) is exposed as `source.trial.movement`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from uareme_fusion.types import ImuBatch

from .base import GroundTruth, Source, SourceInfo
from ..formats.broad import read_broad
from .interleave import IMU_ONLY_BATCH_S, count_spans, split_by_span


class BroadSource(Source):
    """One BROAD trial; see the module docstring."""

    def __init__(self, path: str | Path, batch_s: float = IMU_ONLY_BATCH_S):
        self.trial = read_broad(path)
        self.batch_s = float(batch_s)
        R = self.trial.R_ref_imu
        self._reference_ok = np.all(np.isfinite(R), axis=(1, 2))
        self.n_reference_missing = int((~self._reference_ok).sum())
        self.notes = ([f"{path}: {self.n_reference_missing} samples without optical reference (left out of "
                       "the ground truth)"] if self.n_reference_missing else [])
        self.info = SourceInfo(name=str(path), n_frames=0, fps=None, has_frames=False, has_imu=True)

    @property
    def n_batches(self) -> int:
        """Batches (so estimates) the run will give: the progress bar's length."""
        return count_spans(self.trial.t_s, self.batch_s)

    def events(self) -> Iterator[ImuBatch]:
        yield from split_by_span(self.trial.t_s, self.trial.gyro_rad_s, self.trial.accel_m_s2, self.batch_s)

    def ground_truth(self) -> GroundTruth | None:
        ok = self._reference_ok
        if not ok.any():
            return None
        return GroundTruth(self.trial.t_s[ok], self.trial.R_ref_imu[ok], gravity_aligned=True)
