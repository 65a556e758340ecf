"""A `VisualSequence` for `compare` from any source `run` accepts (a video, a dataset, sim:...), or
from a dataset folder with its normals saved (`load_sequence`).

The source is read once: each frame's normals (`--normals`, as in `run`) are solved into a visual
rotation (each solve initialised from the previous one, `sequence.ChainedSolver`), the IMU samples
are put on the camera clock and axes, and the source's ground truth (or none) is taken at the frame
times. Every backend then runs on these same rotations (`compare.compare`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..drivers.base import ImuBatch, Source
from ..errors import InputError
from ..pipeline.config import RunConfig
from ..pipeline.stages import CappedNormals, make_normal_estimator
from .sequence import ChainedSolver, VisualSequence, solve_frames


def source_sequence(source: Source, cfg: RunConfig, progress=None) -> VisualSequence:
    """Read `source` to its end (or `cfg.max_frames`) into a `VisualSequence`; `progress(done, total)`
    is called after each frame when given."""
    if not source.info.has_frames:
        raise InputError(f"{source.info.name}: 'compare' needs frames to compare visual backends (IMU only)")
    normals = CappedNormals(make_normal_estimator(cfg.normals, source.info, cfg.threads), cfg.kappa_cap)
    t_frames, visuals, imu = [], [], []
    solver = ChainedSolver()
    for event in source.events():
        if isinstance(event, ImuBatch):
            imu.append(event)
            continue
        t_frames.append(event.t)
        visuals.append(solver.solve(normals.estimate_frame(event)))
        if progress is not None:
            progress(len(t_frames), source.info.n_frames)
        if cfg.max_frames and len(t_frames) >= cfg.max_frames:
            break
    if not t_frames:
        raise InputError(f"{source.info.name}: no frames")
    t = np.asarray(t_frames, float)
    notes = [f"{source.info.name}: {len(t)} frames, normals {normals.name}"]
    if solver.invalid:
        notes.append(f"{solver.invalid} frames had no valid normals and gave no visual rotation")
    imu_arrays = camera_imu(imu, source.info.R_ci, source.info.imu_time_offset_s) if imu else (None, None, None)
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
    return VisualSequence(source.info.name, t, visuals, *imu_arrays, R_wc_true, notes)


def camera_imu(batches: list[ImuBatch], R_ci: np.ndarray, imu_time_offset_s: float):
    """(t_s (M,) on the camera clock, gyro (M, 3) rad/s, accel (M, 3) m/s^2 in camera axes) of IMU
    batches, with `R_ci` and the offset of `SourceInfo` (the backends of `compare` take camera-axes IMU)."""
    t_s = np.concatenate([b.t_s for b in batches]) + imu_time_offset_s
    gyro, accel = np.concatenate([b.gyro_rad_s for b in batches]), np.concatenate([b.accel_m_s2 for b in batches])
    if not np.allclose(R_ci, np.eye(3)):
        R_ci = np.asarray(R_ci, float)
        gyro, accel = gyro @ R_ci.T, accel @ R_ci.T
    return t_s, gyro, accel


def load_sequence(source: str | Path) -> VisualSequence:
    """A dataset folder with its normals saved: its normals are solved once per frame.

    A folder written by `uareme-fusion simulate` (a `normals/` folder of per-frame `.npz`) is read by
    its driver (`drivers.tum.TumSource`, with the simulator's normals), as `run` reads it. Otherwise
    `normals.npz` holds `normals` (N, H, W, 3), optional `kappa` (N, H, W) and `t_s` (N,) (else the
    frame times of `rgb.txt`), beside the same driver's files: `groundtruth.txt` (TUM, camera to
    world, slerped at the frame times), `imu0/data.csv` (EuRoC) and `scene.json` (IMU rotation and
    time offset). Missing ground truth or IMU is allowed and noted; a missing folder or missing
    normals is an `InputError`.
    """
    root = Path(source)
    if not root.exists():
        raise InputError(f"{root}: no such dataset folder")
    if not root.is_dir():
        raise InputError(f"{root}: expected a dataset folder written by 'uareme-fusion simulate', got a file")
    if (root / "normals.npz").is_file():
        return _stacked_normals_sequence(root)
    if not (root / "normals").is_dir():
        raise InputError(f"{root}: no normals (expected normals.npz or a normals/ folder of .npz files)")
    from ..drivers.tum import TumSource

    with TumSource(root) as tum:
        if tum.normal_files is None:
            raise InputError(f"{root / 'normals'}: no .npz normal maps for the frames of rgb.txt")
        seq = source_sequence(tum, RunConfig(normals="source"))
    return VisualSequence(root.name, seq.t_frame_s, seq.visuals, seq.imu_t_s, seq.imu_gyro_rad_s,
                          seq.imu_accel_m_s2, seq.R_wc_true, seq.notes + tum.notes)


def _stacked_normals_sequence(root: Path) -> VisualSequence:
    """`normals.npz` with the TUM/EuRoC files of `drivers.tum` beside it (see `load_sequence`)."""
    from ..drivers.imu_csv import read_imu_log
    from ..drivers.tum import ground_truth_from_tum, read_metadata
    from ..drivers.tum_rgbd import read_tum_list, read_tum_trajectory
    from ..types import NormalMap

    stacked, notes = root / "normals.npz", []
    try:
        with np.load(stacked) as data:
            if "normals" not in data:
                raise InputError(f"{stacked}: no array named 'normals' (found {', '.join(data.files)})")
            normals = data["normals"]
            kappa = data["kappa"] if "kappa" in data else np.ones(normals.shape[:-1], np.float32)
            t_frame = data["t_s"] if "t_s" in data else None
    except (OSError, ValueError) as exc:
        raise InputError(f"{stacked}: not a readable .npz file ({exc})") from None
    if normals.ndim != 4 or normals.shape[-1] != 3:
        raise InputError(f"{stacked}: expected normals of shape (N, H, W, 3), got {normals.shape}")
    if t_frame is None:
        if not (root / "rgb.txt").is_file():
            raise InputError(f"{root / 'rgb.txt'}: missing (needed for the frame times of the normal maps)")
        t_frame, _ = read_tum_list(root / "rgb.txt")
    t_frame = np.asarray(t_frame, dtype=float)
    if len(t_frame) != len(normals):
        raise InputError(f"{root}: {len(normals)} normal maps but {len(t_frame)} frame times")
    visuals, invalid = solve_frames([NormalMap(n, k) for n, k in zip(normals, kappa)])
    if invalid:
        notes.append(f"{invalid} normal maps had no valid normals and gave no visual rotation")
    R_wc_true, gt_path = None, root / "groundtruth.txt"
    if gt_path.is_file():
        R_wc_true, in_span = ground_truth_from_tum(read_tum_trajectory(gt_path), gravity_aligned=True).at(t_frame)
        if not in_span.all():
            raise InputError(f"{gt_path}: ground truth covers {int(in_span.sum())} of the {len(t_frame)} frame "
                             f"times ({t_frame[0]:.3f}-{t_frame[-1]:.3f} s)")
    else:
        notes.append("no groundtruth.txt: ARE, tilt and NEES not computed")
    imu_arrays = (None, None, None)
    if (root / "imu0" / "data.csv").is_file():
        imu, _ = read_imu_log(root / "imu0" / "data.csv")
        meta = read_metadata(root)
        R_ci = meta["R_ci"] if meta.get("R_ci") is not None else np.eye(3)
        imu_arrays = camera_imu([ImuBatch(imu.t_s, imu.gyro_rad_s, imu.accel_m_s2)], R_ci,
                                meta.get("imu_time_offset_s", 0.0))
    else:
        notes.append("no imu0/data.csv: IMU backends run without IMU or are skipped")
    return VisualSequence(root.name, t_frame, visuals, *imu_arrays, R_wc_true, notes)
