"""EuRoC MAV sequences (ASL layout) as a `Source`: `mav0/cam0` images, `mav0/imu0` and the state
ground truth.

    with EurocSource("V1_02_medium") as src: ...    # the folder holding mav0/, or mav0/ itself

Read: `cam0/data.csv` (`#timestamp [ns],filename`) with `cam0/data/<file>` (grayscale, converted to
RGB uint8); `cam0/sensor.yaml` (`T_BS` camera-to-body 4x4, `intrinsics` [fu, fv, cu, cv],
`distortion_coefficients` radial-tangential [k1, k2, p1, p2]); `imu0/data.csv`; the ground truth
`gt0/data.csv` or `state_groundtruth_estimate0/data.csv` (`timestamp, p xyz, q_RS w x y z, ...`).
Times: integer nanoseconds -> float seconds (camera and IMU share the clock).

Frames: undistorted to the pinhole `K` = [[fu, 0, cu], [0, fv, cv], [0, 0, 1]] (`undistort=True`,
the default, so K describes the yielded pixels). Without `cam0` the source is IMU-only
(`has_frames` False, batches of `IMU_ONLY_BATCH_S`).

Conventions: the body frame B is the IMU frame (EuRoC's imu0 `T_BS` is the identity), so
`R_ci = R_BS_cam^T` (IMU to camera). Ground truth `q_RS` maps body to the gravity-aligned Vicon/Leica
world R: `R_wc = R_RS @ R_BS_cam` (camera to world, z up); without cam0 it is the body attitude R_wi.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.io.images import read_image
from uareme_fusion.io.text_tables import read_table
from uareme_fusion.types import Frame, ImuBatch

from ..formats.euroc import read_euroc_ground_truth
from ..formats.images import to_rgb8
from .base import GroundTruth, Source, SourceInfo
from .imu_csv import non_increasing_note, read_imu_log
from .interleave import IMU_ONLY_BATCH_S, interleave, split_by_span
from .intrinsics import CameraModel, Undistorter, read_camera_file, read_camera_mapping

GT_FOLDERS = ("gt0", "state_groundtruth_estimate0")
CAM_COLUMNS = ("timestamp [ns]", "filename")


def find_mav0(path: Path) -> Path | None:
    """`path` itself when it holds imu0/ or cam0/, else `path/mav0` when that does; None otherwise."""
    for candidate in (path, path / "mav0"):
        if (candidate / "imu0").is_dir() or (candidate / "cam0").is_dir():
            return candidate
    return None


def camera_calibration(path: Path) -> tuple[CameraModel, np.ndarray]:
    """(camera model: K and distortion, R_BS (3, 3) camera to body) from cam0/sensor.yaml."""
    camera = read_camera_file(path)
    data = read_camera_mapping(path)
    try:
        T_BS = np.asarray(data["T_BS"]["data"], float).reshape(4, 4)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: expected T_BS.data (16 numbers) ({exc!r})") from None
    R_BS = T_BS[:3, :3]
    if not np.allclose(R_BS @ R_BS.T, np.eye(3), atol=1e-4):
        raise InputError(f"{path}: T_BS's rotation block is not a rotation: {R_BS.tolist()}")
    U, _, Vt = np.linalg.svd(R_BS)  # re-orthonormalise the printed digits
    return camera, U @ Vt


class EurocSource(Source):
    """An EuRoC MAV folder; see the module docstring."""

    def __init__(self, root: str | Path, undistort: bool = True, use_imu: bool = True):
        root = Path(root)
        if not root.exists():
            raise InputError(f"EuRoC folder {root}: no such folder")
        mav0 = find_mav0(root)
        if mav0 is None:
            raise InputError(f"EuRoC folder {root}: neither {root}/mav0/ nor {root} holds cam0/ or imu0/")
        self.mav0 = mav0
        self.notes: list[str] = []
        self.K, self.K_origin = None, None
        self.R_BS_cam = np.eye(3)
        self._undistorter: Undistorter | None = None
        self._size: tuple[int, int] | None = None
        self.frame_t_s, self.frame_paths = np.zeros(0), []
        cam0 = mav0 / "cam0"
        if cam0.is_dir():
            self._open_camera(cam0, undistort)
        imu_csv = mav0 / "imu0" / "data.csv"
        self.imu, self.fixes = read_imu_log(imu_csv) if use_imu and imu_csv.is_file() else (None, [])
        if self.imu is None and not self.frame_paths:
            raise InputError(f"EuRoC folder {mav0}: has neither cam0/data.csv nor imu0/data.csv")
        if self.imu is not None:
            self.notes += non_increasing_note(self.imu)
        has_frames = len(self.frame_paths) > 0
        fps = float(1.0 / np.median(np.diff(self.frame_t_s))) if len(self.frame_t_s) > 1 else None
        self.info = SourceInfo(name=str(root), n_frames=len(self.frame_paths) if has_frames else 0,
                               fps=fps, K=self.K, K_origin=self.K_origin, has_frames=has_frames,
                               has_imu=self.imu is not None,
                               R_ci=self.R_BS_cam.T.copy(), image_size=self._size)

    def _open_camera(self, cam0: Path, undistort: bool) -> None:
        listing = cam0 / "data.csv"
        if not listing.is_file():
            raise InputError(f"EuRoC camera folder {cam0}: data.csv (the image list) is missing")
        table = read_table(listing, CAM_COLUMNS, delimiter=",", kind="an EuRoC camera list")
        if len(table) == 0:
            raise InputError(f"{listing}: lists no images")
        t_ns = table.ints(0)
        table.require_increasing(t_ns)
        paths = [cam0 / "data" / name.strip() for name in table.strings(1)]
        exists = np.array([p.is_file() for p in paths])
        if not exists.any():
            raise InputError(f"{listing}: none of the {len(paths)} listed images exist under {cam0 / 'data'}")
        if not exists.all():
            self.notes.append(f"{listing}: {int((~exists).sum())} listed images do not exist and were left out")
        self.frame_t_s = t_ns[exists] * 1e-9
        self.frame_paths = [p for p, ok in zip(paths, exists) if ok]
        first = read_image(self.frame_paths[0], cv2.IMREAD_UNCHANGED, what="an EuRoC camera image")
        self._size = first.shape[:2]
        sensor = cam0 / "sensor.yaml"
        if sensor.is_file():
            camera, self.R_BS_cam = camera_calibration(sensor)
            self.K, self.K_origin = camera.K, str(sensor)
            if undistort and camera.distorted:
                self._undistorter = Undistorter(camera, self._size)
        else:
            self.notes.append(f"{cam0}: no sensor.yaml: intrinsics unknown, camera assumed aligned with the IMU")

    def read_frame(self, i: int) -> Frame:
        try:
            image = read_image(self.frame_paths[i], cv2.IMREAD_UNCHANGED, what=f"EuRoC image {i}")
        except InputError as exc:
            raise SourceError(str(exc)) from None
        if self._undistorter is not None:
            image = self._undistorter.image(image)
        return Frame(t_s=float(self.frame_t_s[i]), rgb=to_rgb8(image), K=self.K, index=i)

    def events(self) -> Iterator[Frame | ImuBatch]:
        if self.imu is None:
            batches = None
        elif self.info.has_frames:
            batches = [ImuBatch(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2)]
        else:
            yield from split_by_span(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2, IMU_ONLY_BATCH_S)
            return
        yield from interleave((self.read_frame(i) for i in range(len(self.frame_paths))), batches)

    def ground_truth(self) -> GroundTruth | None:
        for name in GT_FOLDERS:
            path = self.mav0 / name / "data.csv"
            if path.is_file():
                break
        else:
            return None
        t_s, R_RS = read_euroc_ground_truth(path)
        return GroundTruth(t_s, R_RS @ self.R_BS_cam, gravity_aligned=True)
