"""TUM RGB-D style folders as a `Source`: TUM RGB-D itself, the `simulate` output and `--record` folders.

    with TumSource("rgbd_dataset_freiburg1_desk") as src: ...
    with TumSource("sim_out/") as src: ...      # + imu0, normals, scene.json

What is read (built on `formats.tum.load_tum_rgbd` and `formats.euroc.read_euroc_imu`):
- `rgb.txt` + `depth.txt` (or `associations.txt`): RGB uint8 frames and depth in metres (0 = none).
- `imu0/data.csv` (EuRoC format): gyro + accelerometer batches between frames; `has_imu` True.
- `accelerometer.txt` alone (the TUM Kinect's accelerometer, no gyro): NOT yielded, because the
  backends integrate gyro and drop samples without it; `has_imu` stays False and the samples are
  exposed as `source.accelerometer = (t_s (N,), accel_m_s2 (N, 3))`.
- `groundtruth.txt`: `ground_truth()` with `R_wc` per line (camera to world, TUM order x y z w).
- `normals/<index:06d>.npz` (simulator): exact normals in `Frame.normals` (kappa as stored; a
  dropped frame's map has kappa 0 everywhere: no usable pixel).
- `scene.json` (simulator) or `source.json` (`Recorder`): K, `R_ci`, the IMU time offset, depth
  units, and whether the ground-truth world is gravity aligned (z up); both state it, plain TUM
  folders do not (then evaluation aligns a constant rotation).
- Without either, K is the published one when the folder's name identifies the dataset
  (`rgbd_dataset_freiburg{1,2,3}_*`, `intrinsics.published_camera`); frames (rgb and depth) are then
  undistorted with the published distortion and carry that K. `info.K_origin` says which.

Clocks: frame times are the list's seconds; IMU batches keep the IMU clock
(`info.imu_time_offset_s` from scene.json or source.json is added to put them on the camera clock).
A TUM RGB-D folder (named as one, without scene.json or source.json) has its ground truth's stamps
shifted by `formats.tum.TUM_RGBD_GT_TIME_OFFSET_S` onto the Kinect's clock, said in a note and in
`info.gt_time_offset_s`; every other folder's ground truth is read as stamped (`gt_time_offset_s` 0).
"""

from __future__ import annotations

import dataclasses
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.rotations import is_rotation
from uareme_fusion.types import Frame, ImuBatch, NormalMap

from ..formats.datasets import RENDERED_DEPTH_DATASETS
from ..formats.tum import TUM_RGBD_GT_TIME_OFFSET_S, TumSequence, load_tum_rgbd, read_json_object, read_tum_list
from .base import PLATFORMS, GroundTruth, Source, SourceInfo
from .imu_csv import non_increasing_note, read_imu_log
from .interleave import interleave
from .intrinsics import CameraModel, Undistorter, published_camera, published_dataset

SIM_META = "scene.json"
RECORD_META = "source.json"
NORMALS_DIR = "normals"


def _matrix(meta: dict, key: str, path: Path, rotation: bool = False) -> np.ndarray | None:
    if key not in meta or meta[key] is None:
        return None
    try:
        M = np.asarray(meta[key], dtype=float)
    except (TypeError, ValueError):
        M = None
    if M is None or M.shape != (3, 3) or not np.all(np.isfinite(M)):
        raise InputError(f"{path}: {key} must be a 3x3 matrix of numbers, got {meta[key]!r}")
    if rotation and not is_rotation(M, atol=1e-5):
        raise InputError(f"{path}: {key} must be a rotation matrix (orthonormal, det +1), got {M.tolist()}")
    return M


def _number(meta: dict, key: str, path: Path, default: float | None, positive: bool = False) -> float | None:
    value = meta.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or (
            positive and value <= 0):
        raise InputError(f"{path}: {key} must be a {'positive ' if positive else ''}number, got {value!r}")
    return float(value)


def read_metadata(root: Path) -> dict:
    """K, R_ci, imu_time_offset_s (SourceInfo convention), depth_scale, fps, gravity_aligned from
    `source.json` or `scene.json` in `root` ({} when neither exists); `InputError` naming the file
    and key for a bad value."""
    for name in (RECORD_META, SIM_META):
        path = root / name
        if path.is_file():
            break
    else:
        return {}
    meta = read_json_object(path)
    if name == SIM_META and "imu_time_offset_s" not in meta and meta.get("time_offset_s"):
        raise InputError(f"{path}: time_offset_s is the old, opposite-sign key (IMU clock minus camera clock); "
                         f"write imu_time_offset_s = {-float(meta['time_offset_s'])!r} instead, or simulate again")
    offset = _number(meta, "imu_time_offset_s", path, 0.0)
    gravity_aligned = True if name == SIM_META else bool(meta.get("gravity_aligned", False))
    return dict(path=path, K=_matrix(meta, "K", path), R_ci=_matrix(meta, "R_ci", path, rotation=True),
                imu_time_offset_s=offset, depth_scale=_number(meta, "depth_scale", path, None, positive=True),
                fps=_number(meta, "fps", path, None, positive=True), gravity_aligned=gravity_aligned,
                platform=_platform(meta, path))


def _platform(meta: dict, path: Path) -> str | None:
    value = meta.get("platform")
    if value is None or value in PLATFORMS:
        return value
    raise InputError(f"{path}: platform must be one of {', '.join(PLATFORMS)}, got {value!r}")


def ground_truth_from_tum(trajectory: tuple[np.ndarray, np.ndarray, np.ndarray], gravity_aligned: bool,
                          time_scale: float = 1.0, R_fix=None) -> GroundTruth:
    """`GroundTruth` from a TUM trajectory (t, p, quat_xyzw) holding `R_wc`; `R_fix` maps the stored
    rotations (N, 3, 3) to OpenCV camera axes when a dataset needs it (ICL-NUIM)."""
    t, _, quat_xyzw = trajectory
    R_wc = Rotation.from_quat(quat_xyzw).as_matrix()
    if R_fix is not None:
        R_wc = R_fix(R_wc)
    order = np.argsort(t, kind="stable")
    return GroundTruth(np.asarray(t, float)[order] * time_scale, R_wc[order], gravity_aligned)


def read_frame_normals(path: Path, t: float | None = None) -> NormalMap:
    """One `normals/<index>.npz` of a simulated folder: `normals` (H, W, 3) and `kappa` (H, W), kappa
    0 everywhere when `dropped` (the camera failed on that frame: no pixel is usable); an
    `InputError` naming the file otherwise."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            normals = np.asarray(npz["normals"], np.float32)
            kappa = np.asarray(npz["kappa"], np.float32)
            dropped = bool(npz["dropped"]) if "dropped" in npz else False
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a readable normals file with arrays 'normals' and 'kappa' ({exc})") from None
    if normals.ndim != 3 or normals.shape[2] != 3 or kappa.shape != normals.shape[:2]:
        raise InputError(f"{path}: expected normals (H, W, 3) and kappa (H, W), got {normals.shape}, {kappa.shape}")
    if dropped:
        kappa = np.zeros_like(kappa)
    return NormalMap(normals, kappa, t_s=t)


class TumSource(Source):
    """A TUM RGB-D style folder; see the module docstring. Options: `use_imu` (read imu0 when
    present), `use_normals` (attach normals/*.npz), `max_dt_s` (rgb-depth pairing tolerance)."""

    time_scale: float = 1.0
    """Seconds per unit of the lists' timestamps (ICL-NUIM counts frames)."""

    def __init__(self, root: str | Path, use_imu: bool = True, use_normals: bool = True, max_dt_s: float = 0.02):
        self.root = Path(root)
        if not self.root.is_dir():
            raise InputError(f"dataset folder {self.root}: no such folder")
        self.meta = read_metadata(self.root)
        self.seq: TumSequence = load_tum_rgbd(self.root, depth_scale=self.meta.get("depth_scale"), max_dt_s=max_dt_s)
        self.camera = self._camera()
        self.seq = dataclasses.replace(self.seq, K=None if self.camera is None else self.camera.K)
        self.t_s = self.seq.t_s * self.time_scale
        self.notes: list[str] = []
        """What was left out or not used, for the run summary (nothing is skipped silently)."""
        if self.seq.n_missing:
            self.notes.append(f"{self.root}: {self.seq.n_missing} listed rgb images do not exist and were left out")
        if self.seq.n_unpaired:
            self.notes.append(f"{self.root}: {self.seq.n_unpaired} rgb images have no depth image within "
                              f"{max_dt_s} s (yielded without depth)")
        self.imu = None
        imu_csv = self.root / "imu0" / "data.csv"
        self.fixes: list[str] = []
        if use_imu and imu_csv.is_file():
            self.imu, self.fixes = read_imu_log(imu_csv)
            self.notes += non_increasing_note(self.imu)
        self.accelerometer = self.seq.accelerometer
        if self.imu is None and self.accelerometer is not None:
            self.notes.append(f"{self.root}/accelerometer.txt has no gyro: not used as IMU input "
                              "(available as source.accelerometer)")
        self.normal_files = self._normal_files() if use_normals else None
        fps = self.meta.get("fps")
        if fps is None and len(self.t_s) > 1:
            fps = float(1.0 / np.median(np.diff(self.t_s)))
        first = self.seq.read_frame(0) if len(self.seq) else None
        self._undistorter = (Undistorter(self.camera, first.rgb.shape[:2])
                             if first is not None and self.camera is not None and self.camera.distorted else None)
        dataset = published_dataset(self.root)
        rendered = (self.root / SIM_META).is_file() or (dataset is not None and dataset[0] in RENDERED_DEPTH_DATASETS)
        self._gt_offset_s = self._gt_time_offset_s(dataset)
        self.info = SourceInfo(
            name=str(root), n_frames=len(self.seq), fps=fps, K=self.seq.K,
            K_origin=None if self.camera is None else self.camera.origin,
            has_depth=any(p is not None for p in self.seq.depth_paths), has_imu=self.imu is not None,
            R_ci=self.meta.get("R_ci") if self.meta.get("R_ci") is not None else np.eye(3),
            imu_time_offset_s=self.meta.get("imu_time_offset_s", 0.0), platform=self.meta.get("platform"),
            image_size=None if first is None else first.rgb.shape[:2],
            depth_rendered=rendered, gt_time_offset_s=self._gt_offset_s,
        )

    def _gt_time_offset_s(self, dataset: tuple[str, str] | None) -> float:
        """The dataset default shift of the ground truth's stamps (module docstring), with its note."""
        if self.seq.groundtruth is None or self.meta or dataset is None or not dataset[0].startswith("TUM RGB-D"):
            return 0.0
        self.notes.append(f"{self.root / 'groundtruth.txt'}: stamps {TUM_RGBD_GT_TIME_OFFSET_S * 1000:+.0f} ms onto "
                          f"the Kinect's clock (the TUM RGB-D default; --gt-time-offset-s to change)")
        return TUM_RGBD_GT_TIME_OFFSET_S

    def _camera(self) -> CameraModel | None:
        """K from source.json / scene.json, else the published intrinsics the folder's name identifies
        (TUM RGB-D freiburg1-3, with their distortion), else None."""
        if self.meta.get("K") is not None:
            return CameraModel(self.meta["K"], np.zeros(0), origin=str(self.meta["path"]))
        if self.seq.K is not None:
            return CameraModel(self.seq.K, np.zeros(0), origin=str(self.root / SIM_META))
        return published_camera(self.root)

    def _normal_files(self) -> list[Path | None] | None:
        """normals/<i>.npz for each kept frame, i its line in rgb.txt (None where absent)."""
        folder = self.root / NORMALS_DIR
        if not folder.is_dir() or not (self.root / "rgb.txt").is_file():
            return None
        _, listed = read_tum_list(self.root / "rgb.txt")
        line_of = {str(self.root / f): i for i, f in enumerate(listed)}
        files = [folder / f"{line_of[str(p)]:06d}.npz" for p in self.seq.rgb_paths]
        found = [p if p.is_file() else None for p in files]
        missing = sum(p is None for p in found)
        if missing == len(found):
            return None
        if missing:
            self.notes.append(f"{folder}: {missing} frames have no normals file (yielded without normals)")
        return found

    def _normals(self, i: int, t_s: float) -> NormalMap | None:
        if self.normal_files is None or self.normal_files[i] is None:
            return None
        try:
            return read_frame_normals(self.normal_files[i], t_s)
        except InputError as exc:  # met mid-stream: the source fails there
            raise SourceError(str(exc)) from None

    def read_frame(self, i: int) -> Frame:
        """Frame i with depth, K and normals; `SourceError` naming the file that cannot be read."""
        try:
            frame = self.seq.read_frame(i)
        except InputError as exc:
            raise SourceError(str(exc)) from None
        if self._undistorter is not None:
            frame = self._undistorter.frame(frame)
        t = float(self.t_s[i])
        return dataclasses.replace(frame, t_s=t, normals=self._normals(i, t))

    def _frames(self) -> Iterator[Frame]:
        for i in range(len(self.seq)):
            yield self.read_frame(i)

    def _imu_batches(self):
        if self.imu is None:
            return None
        return [ImuBatch(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2)]

    def events(self) -> Iterator:
        yield from interleave(self._frames(), self._imu_batches(), self.info.imu_time_offset_s)

    def ground_truth(self) -> GroundTruth | None:
        if self.seq.groundtruth is None:
            return None
        truth = ground_truth_from_tum(self.seq.groundtruth, bool(self.meta.get("gravity_aligned", False)),
                                      self.time_scale)
        return dataclasses.replace(truth, t_s=truth.t_s + self._gt_offset_s)
