"""A `VisualSequence` for `compare` from any source `run` accepts (a video, a dataset, sim:...), or
from a dataset folder with its normals saved (`load_sequence`).

The source is read once: each frame's cues (`--cues`: normals as `--normals` says, and/or line
segments, as in `run`) are solved into a visual rotation (each solve initialised from the previous one,
`sequence.ChainedSolver`), the IMU samples are put on the camera clock and axes, and the source's ground
truth (or none) is taken at the frame times. Every backend then runs on these same rotations (`compare.compare`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..drivers.base import ImuBatch, Source
from ..errors import InputError
from ..pipeline.config import RunConfig
from .sequence import ChainedSolver, VisualSequence, solve_frames


def source_sequence(source: Source, cfg: RunConfig, progress=None) -> VisualSequence:
    """Read `source` to its end (or `cfg.max_frames`) into a `VisualSequence`; `progress(done, total)`
    is called after each frame when given."""
    if not source.info.has_frames:
        raise InputError(f"{source.info.name}: 'compare' needs frames to compare visual backends (IMU only)")
    from ..solver.cues import parse_cues, pool_before_run
    from ..pipeline.session import visual_stages

    cues = parse_cues(cfg.cues)
    normals, cue_solver = visual_stages(cfg, source.info)
    pool_before_run(cue_solver, source, cfg.max_frames)  # as a run does
    t_frames, visuals, imu = [], [], []
    solver = ChainedSolver(cue_solver)
    for event in source.events():
        if isinstance(event, ImuBatch):
            imu.append(event)
            continue
        t_frames.append(event.t_s)
        visuals.append(solver.solve(normals.estimate_frame(event) if normals is not None else None, event))
        if progress is not None:
            progress(len(t_frames), source.info.n_frames)
        if cfg.max_frames and len(t_frames) >= cfg.max_frames:
            break
    if not t_frames:
        raise InputError(f"{source.info.name}: no frames")
    t = np.asarray(t_frames, float)
    notes = [f"{source.info.name}: {len(t)} frames, cues {','.join(cues)}"
             + (f", normals {normals.name}" if normals is not None else "")]
    if solver.invalid:
        notes.append(f"{solver.invalid} frames had no valid normals or segments and gave no visual rotation")
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
    """A dataset folder with its normals saved (`uareme-fusion simulate` writes one): its normals are
    solved once per frame.

    Normals: `normals.npz` with `normals` (N, H, W, 3), optional `kappa` (N, H, W) and `t_s` (N,),
    or a folder `normals/` of per-frame `.npz` files (sorted by name; `drivers.tum.read_frame_normals`,
    so a frame the simulator dropped has no usable pixel, as in `run`) with frame times from `rgb.txt`.
    The rest is read by the TUM driver's readers (`drivers.tum`): ground truth from `groundtruth.txt`
    (camera to world, slerped at the frame times, `GroundTruth.at`; it must span them), IMU from `imu0/data.csv` (EuRoC)
    with the rotation and time offset of `scene.json`. Missing ground truth or IMU is allowed and
    noted; a missing folder or missing normals is an `InputError`.
    """
    from ..formats.euroc import read_euroc_imu
    from ..drivers.tum import ground_truth_from_tum, read_metadata
    from ..formats.tum import read_tum_list, read_tum_trajectory

    root = Path(source)
    if not root.exists():
        raise InputError(f"{root}: no such dataset folder")
    if not root.is_dir():
        raise InputError(f"{root}: expected a dataset folder written by 'uareme-fusion simulate', got a file")
    maps, t_frame, notes = _saved_normal_maps(root)
    if t_frame is None:
        if not (root / "rgb.txt").is_file():
            raise InputError(f"{root / 'rgb.txt'}: missing (needed for the frame times of the normal maps)")
        t_frame, _ = read_tum_list(root / "rgb.txt")
    t_frame = np.asarray(t_frame, dtype=float)
    if len(t_frame) != len(maps):
        raise InputError(f"{root}: {len(maps)} normal maps but {len(t_frame)} frame times")
    visuals, invalid = solve_frames(maps)
    if invalid:
        notes.append(f"{invalid} normal maps had no valid normals and gave no visual rotation")
    R_wc_true, gt_path = None, root / "groundtruth.txt"
    if gt_path.is_file():
        truth = ground_truth_from_tum(read_tum_trajectory(gt_path), gravity_aligned=True)
        if len(truth.t_s) == 0 or t_frame[0] < truth.t_s[0] or t_frame[-1] > truth.t_s[-1]:
            span = f"{truth.t_s[0]:.3f}-{truth.t_s[-1]:.3f} s" if len(truth.t_s) else "no time"
            raise InputError(f"{gt_path}: ground truth covers {span} but frames span "
                             f"{t_frame[0]:.3f}-{t_frame[-1]:.3f} s")
        R_wc_true, _ = truth.at(t_frame)
    else:
        notes.append("no groundtruth.txt: ARE, tilt and NEES not computed")
    imu_arrays = (None, None, None)
    if (root / "imu0" / "data.csv").is_file():
        imu = read_euroc_imu(root / "imu0" / "data.csv")
        meta = read_metadata(root)
        R_ci = meta["R_ci"] if meta.get("R_ci") is not None else np.eye(3)
        imu_arrays = camera_imu([ImuBatch(imu.t_s, imu.gyro_rad_s, imu.accel_m_s2)], R_ci,
                                meta.get("imu_time_offset_s", 0.0))
    else:
        notes.append("no imu0/data.csv: IMU backends run without IMU or are skipped")
    return VisualSequence(root.name, t_frame, visuals, *imu_arrays, R_wc_true, notes)


def _saved_normal_maps(root: Path) -> tuple[list, np.ndarray | None, list]:
    """(normal maps, their times or None, notes) from `normals.npz` or `normals/*.npz` in `root`."""
    from ..drivers.tum import read_frame_normals
    from ..types import NormalMap

    stacked = root / "normals.npz"
    if stacked.is_file():
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
        return [NormalMap(n, k) for n, k in zip(normals, kappa)], t_frame, []
    if (root / "normals").is_dir():
        files = sorted((root / "normals").glob("*.npz"))
        if not files:
            raise InputError(f"{root / 'normals'}: no .npz normal maps")
        return [read_frame_normals(f) for f in files], None, []
    raise InputError(f"{root}: no normals (expected normals.npz or a normals/ folder of .npz files)")
