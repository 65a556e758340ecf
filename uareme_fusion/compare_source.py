"""A `VisualSequence` for `compare` from any source `run` accepts (a video, a dataset, sim:...).

The source is read once: each frame's cues (`--cues`: normals as `--normals` says, and/or line
segments, as in `run`) are solved into a visual rotation (`pipeline.cues.CueSolver`) (each solve initialised from the previous one, as `compare.solve_frames` does), the IMU
samples are kept on the camera clock, and the source's ground truth (or none) is taken at the
frame times. Every backend then runs on these same rotations (`compare.compare`).
"""

from __future__ import annotations

import numpy as np

from .compare import VisualSequence
from .drivers.base import ImuBatch, Source
from .errors import InputError
from .pipeline.config import RunConfig
from .pipeline.cues import CueSolver, parse_cues
from .pipeline.stages import CappedNormals, make_normal_estimator


def source_sequence(source: Source, cfg: RunConfig, progress=None) -> VisualSequence:
    """Read `source` to its end (or `cfg.max_frames`) into a `VisualSequence`; `progress(done, total)`
    is called after each frame when given."""
    if not source.info.has_frames:
        raise InputError(f"{source.info.name}: 'compare' needs frames to compare visual backends (IMU only)")
    cues = parse_cues(cfg.cues)
    normals = (CappedNormals(make_normal_estimator(cfg.normals, source.info, cfg.threads), cfg.kappa_cap)
               if "normals" in cues else None)
    solver = CueSolver(lines="lines" in cues)
    t_frames, visuals, imu = [], [], []
    R_prev, invalid = None, 0
    for event in source.events():
        if isinstance(event, ImuBatch):
            imu.append(event)
            continue
        normal_map = normals.estimate_frame(event) if normals is not None else None
        visual = solver.solve(event, normal_map, R_init=R_prev)
        if visual is None:  # no valid normals nor segments (as in `compare.solve_frames`)
            invalid += 1
        else:
            R_prev = visual.R_cm
        t_frames.append(event.t)
        visuals.append(visual)
        if progress is not None:
            progress(len(t_frames), source.info.n_frames)
        if cfg.max_frames and len(t_frames) >= cfg.max_frames:
            break
    if not t_frames:
        raise InputError(f"{source.info.name}: no frames")
    t = np.asarray(t_frames, float)
    notes = [f"{source.info.name}: {len(t)} frames, cues {','.join(cues)}"
             + (f", normals {normals.name}" if normals is not None else "")]
    if invalid:
        notes.append(f"{invalid} frames had no valid normals or segments and gave no visual rotation")
    imu_t = imu_gyro = imu_accel = None
    if imu:
        offset = source.info.imu_time_offset_s
        imu_t = np.concatenate([b.t_s for b in imu]) + offset
        imu_gyro, imu_accel = np.concatenate([b.gyro_rad_s for b in imu]), np.concatenate([b.accel_m_s2 for b in imu])
        if not np.allclose(source.info.R_ci, np.eye(3)):
            R_ci = np.asarray(source.info.R_ci, float)  # the backends of `compare` take camera-axes IMU
            imu_gyro, imu_accel = imu_gyro @ R_ci.T, imu_accel @ R_ci.T
    R_wc_true = None
    truth = source.ground_truth()
    if truth is not None:
        R_true, in_span = truth.at(t)
        if in_span.all():
            R_wc_true = R_true
            if not truth.gravity_aligned:
                notes.append("the reference world is not gravity-aligned: tilt errors are against its z axis")
        else:
            notes.append(f"ground truth covers {int(in_span.sum())} of {len(t)} frames: errors not computed")
    return VisualSequence(source.info.name, t, visuals, imu_t, imu_gyro, imu_accel, R_wc_true, notes)
