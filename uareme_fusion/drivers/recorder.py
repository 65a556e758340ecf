"""Recording any source to disk in the `simulate` layout, so a live session replays through `TumSource`.

    with record(open_source("oak"), "session1/") as src:   # a Source: events pass through and are written
        for event in src.events(): ...
    with TumSource("session1/") as replay: ...              # the same frames, IMU and times

Layout written (through `io.safe_files`: images, `.npz`, `groundtruth.txt` and `source.json` whole
and atomically; the lists and `imu0/data.csv` streamed in whole rows, so a crash, Ctrl-C or a full
disk leaves a valid, replayable prefix; files are written before the list line that names them):
- `rgb/<n:06d>.png` 8-bit RGB (a normals-only frame gets a black image of the normals' size),
  `depth/<n:06d>.png` 16-bit, `depth_scale` units per metre (default 1000: millimetres, exact for
  OAK depth, 65.5 m range; deeper or non-finite depth is written as 0 = missing and counted);
- `rgb.txt`, `depth.txt`: `timestamp filename` (TUM), timestamps as the shortest decimal that reads
  back to the same float (`repr`), so replayed frame times are bit-identical;
- `imu0/data.csv`: EuRoC, integer nanoseconds (times read back within 0.5 ns), values with 17
  significant digits (read back exactly); IMU clock stamps as the source yielded them;
- `normals/<n:06d>.npz` (`normals`, `kappa`) when frames carry normals;
- `groundtruth.txt` (TUM, `R_wc` as x y z w, zero positions) at close when the source has ground truth;
- `source.json`: K, R_ci, imu_time_offset_s (SourceInfo convention), depth_scale, fps,
  gravity_aligned, the source's name, and at close the counts written.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.errors import InputError, OutputError
from uareme_fusion.formats.depth_png import MILLIMETRE_DEPTH_SCALE, depth_png_units
from uareme_fusion.formats.euroc import EUROC_IMU_HEADER, euroc_imu_text
from uareme_fusion.formats.tum import TUM_TRAJECTORY_HEADER, tum_trajectory_line
from uareme_fusion.io.safe_files import (ReservedFile, RowFile, cannot_write, write_image_atomic, write_npz_atomic,
                                          write_text_atomic)
from uareme_fusion.types import Frame, ImuBatch

from .base import GroundTruth, Source, SourceInfo
from .tum import NORMALS_DIR, RECORD_META

RECORD_DEPTH_SCALE = MILLIMETRE_DEPTH_SCALE
"""Depth PNG units per metre in recordings (millimetres)."""


def _jsonable(matrix) -> list | None:
    return None if matrix is None else np.asarray(matrix, float).tolist()


class Recorder:
    """Writes frames and IMU batches under `out_dir` as they come; see the module docstring."""

    def __init__(self, out_dir: str | Path, info: SourceInfo, depth_scale: float = RECORD_DEPTH_SCALE,
                 overwrite: bool = False):
        self.out = Path(out_dir)
        if self.out.exists() and not self.out.is_dir():
            raise InputError(f"--record {self.out}: exists and is not a folder")
        if self.out.is_dir() and any(self.out.iterdir()) and not overwrite:
            raise InputError(f"--record {self.out}: folder is not empty; choose a new one")
        if not (np.isfinite(depth_scale) and depth_scale > 0):
            raise InputError(f"record depth_scale must be > 0 units per metre, got {depth_scale}")
        for sub in ("rgb", "depth", "imu0"):
            try:
                (self.out / sub).mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise cannot_write(self.out / sub, exc) from None
        self.info, self.depth_scale = info, float(depth_scale)
        self.n_frames = self.n_imu = self.n_depth_dropped = 0
        self.K = info.K
        self._rgb_list = RowFile(self.out / "rgb.txt")
        self._depth_list = RowFile(self.out / "depth.txt")
        self._imu_csv = RowFile(self.out / "imu0" / "data.csv")
        self._rgb_list.write_row(f"# rgb images recorded from {info.name}\n# timestamp filename\n", counts=False)
        self._depth_list.write_row(f"# depth images recorded from {info.name} ({self.depth_scale:g} units per "
                                   "metre)\n# timestamp filename\n", counts=False)
        self._imu_csv.write_row(EUROC_IMU_HEADER + "\n", counts=False)
        self._gravity_aligned = False
        self._meta = ReservedFile(self.out / RECORD_META, self._meta_text())  # room for the counts at close
        self.closed = False

    def _write_meta(self) -> None:
        self._meta.write(self._meta_text())

    def _meta_text(self) -> str:
        info = self.info
        meta = dict(name=info.name, K=_jsonable(self.K), R_ci=_jsonable(info.R_ci),
                    imu_time_offset_s=float(info.imu_time_offset_s), depth_scale=self.depth_scale,
                    fps=info.fps, platform=info.platform, has_imu=info.has_imu, gravity_aligned=self._gravity_aligned,
                    frames=self.n_frames, imu_samples=self.n_imu, depth_pixels_dropped=self.n_depth_dropped,
                    conventions="R_ci maps IMU to camera (v_c = R_ci v_i); an IMU sample stamped t happened at "
                                "camera time t + imu_time_offset_s; groundtruth.txt holds R_wc (camera OpenCV "
                                "axes to world) as quaternions x y z w")
        return json.dumps(meta, indent=1) + "\n"

    def write_frame(self, frame: Frame) -> None:
        n, stamp = self.n_frames, repr(float(frame.t_s))
        rgb = frame.rgb
        if rgb is None:
            shape = frame.normals.normals.shape[:2] if frame.normals is not None else (1, 1)
            rgb = np.zeros((*shape, 3), np.uint8)
        write_image_atomic(self.out / "rgb" / f"{n:06d}.png", np.ascontiguousarray(rgb[..., ::-1]))
        if frame.depth is not None:
            png, n_dropped = depth_png_units(np.asarray(frame.depth, np.float64), self.depth_scale, far="drop")
            self.n_depth_dropped += n_dropped
            write_image_atomic(self.out / "depth" / f"{n:06d}.png", png)
            self._depth_list.write_row(f"{stamp} depth/{n:06d}.png\n")
        if frame.normals is not None:
            write_npz_atomic(self.out / NORMALS_DIR / f"{n:06d}.npz", normals=frame.normals.normals,
                             kappa=frame.normals.kappa)
        self._rgb_list.write_row(f"{stamp} rgb/{n:06d}.png\n")
        if self.K is None and frame.K is not None:
            self.K = frame.K
            self._write_meta()
        self.n_frames += 1

    def write_imu(self, batch: ImuBatch) -> None:
        if not len(batch):
            return
        self._imu_csv.write_row(euroc_imu_text(batch.t_s, batch.gyro_rad_s, batch.accel_m_s2))
        self.n_imu += len(batch)

    def write(self, event: Frame | ImuBatch) -> None:
        if isinstance(event, ImuBatch):
            self.write_imu(event)
        else:
            self.write_frame(event)

    def write_ground_truth(self, truth: GroundTruth) -> None:
        quat = Rotation.from_matrix(truth.R_wc).as_quat(canonical=True)
        rows = "".join(tum_trajectory_line(t, row, fmt=".17g") for t, row in zip(truth.t_s, quat))
        write_text_atomic(self.out / "groundtruth.txt", "# ground truth R_wc (camera OpenCV axes to world), positions "
                          f"unknown (0)\n# {TUM_TRAJECTORY_HEADER}\n" + rows)
        self._gravity_aligned = bool(truth.gravity_aligned)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for fh in (self._rgb_list, self._depth_list, self._imu_csv):
            fh.close()
        if self.n_frames == 0:  # an IMU-only recording: TUM replay needs frames, say so in the metadata
            (self.out / "rgb.txt").unlink()
            (self.out / "depth.txt").unlink()
        self._write_meta()


class RecordingSource(Source):
    """`source` unchanged, with every event written by a `Recorder` on the way through."""

    def __init__(self, source: Source, out_dir: str | Path, **recorder_options):
        self.source = source
        self.info = source.info
        self.notes, self.fixes = source.report()
        self.recorder = Recorder(out_dir, source.info, **recorder_options)
        self.failed: InputError | OutputError | None = None

    def events(self) -> Iterator[Frame | ImuBatch]:
        for event in self.source.events():
            try:
                self.recorder.write(event)
            except (InputError, OutputError) as exc:
                self.failed = exc
                raise
            yield event

    def sample_frames(self, n: int, limit: int | None = None):
        """The recorded source's (a live camera's None: its replay then runs as it did)."""
        return self.source.sample_frames(n, limit)

    def ground_truth(self) -> GroundTruth | None:
        return self.source.ground_truth()

    def close(self) -> None:
        """Ground truth and the final counts are written even after a failed write (the first error is
        the one reported); the source is closed whatever happens."""
        try:
            if not self.recorder.closed:
                try:
                    truth = self.source.ground_truth()
                    if truth is not None:
                        self.recorder.write_ground_truth(truth)
                finally:
                    self.recorder.close()
        except (InputError, OutputError):
            if self.failed is None:
                raise
        finally:
            self.source.close()


def record(source: Source, out_dir: str | Path, **recorder_options) -> Source:
    """`source` with its frames and IMU written to `out_dir` as they pass (`--record DIR`)."""
    return RecordingSource(source, out_dir, **recorder_options)
