"""A run written to an MCAP file that Foxglove opens as it is (`run ... --mcap FILE.mcap`).

Needs the `mcap` library (the `ros` extra: `pip install "uareme-fusion[ros]"`). Channels, JSON
encoding with Foxglove's schemas (`formats.foxglove_json`), log time = the frame's time:
- `/camera/image` (foxglove.CompressedImage): the frame as the pipeline saw it, JPEG, frame_id `camera`;
- `/camera/calibration` (foxglove.CameraCalibration): its K (given, estimated, or assumed from the
  field of view: the annotation says so), no distortion (frames are already undistorted);
- `/camera/annotations` (foxglove.ImageAnnotations): the horizon line `l = K^-T up_c` (green), the
  up vector drawn from the image centre in perspective (yellow, `UP_ARROW_FRACTION` of the image),
  and a text line with roll, pitch, the 1-sigma of the attitude and the status flags;
- `/tf` (foxglove.FrameTransform): `world` -> `camera`, rotation `R_wc` (camera OpenCV axes x right,
  y down, z forward; world z up), so the 3D panel shows the camera's attitude;
- `/estimate` (`uareme.Estimate`): time, quaternion x y z w of R_wc, covariance (3x3 row-major, rad^2,
  right perturbation), 1-sigma per axis in degrees, up in the camera frame, roll and pitch (deg),
  status as an integer and flag names, visual quality. Plot panels take its fields (`/estimate.roll_deg`).
An IMU-only source gives `/tf` and `/estimate` per estimate and no image topics.

Crash safety: each frame's messages are flushed as one chunk (`mcap.writer.Writer.flush`), so a run
that stops early (Ctrl-C, SIGTERM, a kill) leaves every complete frame; a normal end (and Ctrl-C,
which closes the sinks) writes the summary and index. The file is opened under its final name with
`O_NOFOLLOW` (a link in its place is refused); a full disk is an `OutputError` naming it.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, OutputError
from ..formats import foxglove_json as fox
from ..io.safe_files import cannot_write, refuse_link
from ..overlay import intrinsics_or_assumed
from ..overlay.camera import assumed_fov_note
from ..overlay.horizon import HORIZON_RGB, horizon_segment
from ..rotations import quat_xyzw
from ..types import Estimates, FrameResult, Status
from .rerun_file import roll_pitch_deg

CAMERA_FRAME_ID = "camera"
WORLD_FRAME_ID = "world"
JPEG_QUALITY = 90
UP_RGB = (255, 220, 0)
UP_ARROW_FRACTION = 0.2
"""The up arrow is this fraction of the image's smaller side long when parallel to the image plane."""
ESTIMATE_SCHEMA = {
    "title": "uareme.Estimate", "type": "object",
    "properties": {"t_s": {"type": "number"}, "quat_xyzw": {"type": "array", "items": {"type": "number"}},
                   "cov_rad2": {"type": "array", "items": {"type": "number"}},
                   "std_deg": {"type": "object", "properties": {a: {"type": "number"} for a in "xyz"}},
                   "up_c": {"type": "object", "properties": {a: {"type": "number"} for a in "xyz"}},
                   "roll_deg": {"type": "number"}, "pitch_deg": {"type": "number"}, "status": {"type": "integer"},
                   "status_flags": {"type": "array", "items": {"type": "string"}},
                   "visual_quality": {"type": ["number", "null"]}}}
TOPICS = {"/camera/image": "foxglove.CompressedImage", "/camera/calibration": "foxglove.CameraCalibration",
          "/camera/annotations": "foxglove.ImageAnnotations", "/tf": "foxglove.FrameTransform",
          "/estimate": "uareme.Estimate"}


def _mcap_writer():
    try:
        from mcap.writer import CompressionType, Writer
    except ImportError:
        raise InputError("--mcap needs the mcap library: pip install 'uareme-fusion[ros]' (or mcap)") from None
    return Writer, CompressionType


def _finite(values) -> list:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, float).ravel()]


def status_flag_names(status: int) -> list[str]:
    return [flag.name for flag in Status if flag and flag & status]


def estimate_message(t_s: float, R_wc: np.ndarray, cov: np.ndarray, status: int, quality: float | None) -> dict:
    """The `/estimate` message of one estimate (see the module docstring)."""
    up_c = np.asarray(R_wc, float)[2, :]
    roll, pitch = roll_pitch_deg(up_c)
    std = np.degrees(np.sqrt(np.clip(np.diag(cov), 0.0, None)))
    return {"t_s": float(t_s), "quat_xyzw": _finite(quat_xyzw(R_wc)), "cov_rad2": _finite(cov),
            "std_deg": dict(zip("xyz", _finite(std))), "up_c": dict(zip("xyz", _finite(up_c))),
            "roll_deg": roll, "pitch_deg": pitch, "status": int(status), "status_flags": status_flag_names(int(status)),
            "visual_quality": quality}


def up_arrow_px(up_c: np.ndarray, K: np.ndarray, height: int, width: int) -> list[tuple]:
    """Segments (OpenCV pixels) of an arrow from the image centre along world up, in perspective: the
    tip is the image of the centre pixel's ray point at depth 1 moved along `up_c`."""
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    origin_c = np.linalg.solve(K, [centre[0], centre[1], 1.0])
    length = min(0.5, UP_ARROW_FRACTION * min(height, width) / K[0, 0])  # <= 0.5 keeps the tip in front
    tip_h = K @ (origin_c + length * np.asarray(up_c, float))
    tip = tip_h[:2] / tip_h[2]
    shaft = tip - centre
    size = np.linalg.norm(shaft)
    if size < 1e-6:  # up along the optical axis: a dot
        return [(tuple(centre), tuple(centre))]
    back = -shaft / size * min(0.3 * size, 0.05 * min(height, width))
    c, s = np.cos(0.5), np.sin(0.5)  # the head's two strokes, 0.5 rad either side of the shaft
    heads = [tip + np.array([[c, -s], [s, c]]) @ back, tip + np.array([[c, s], [-s, c]]) @ back]
    return [(tuple(centre), tuple(tip)), (tuple(tip), tuple(heads[0])), (tuple(tip), tuple(heads[1]))]


class McapSink:
    """Writes every result to an MCAP file as it comes; see the module docstring."""

    def __init__(self, path: str | Path, fov_deg: float = 60.0):
        Writer, CompressionType = _mcap_writer()
        self.path, self.fov_deg = Path(path), float(fov_deg)
        if self.path.suffix.lower() != ".mcap":
            raise InputError(f"--mcap {self.path}: an MCAP recording is a .mcap file")
        self._file = self._open()
        self.frames = 0
        self._index_ok = True
        self._frame_start = 0
        try:
            self.writer = Writer(self._file, compression=CompressionType.ZSTD)
            self.writer.start(profile="", library="uareme-fusion")
            schemas = {name: self.writer.register_schema(name, "jsonschema", data)
                       for name, data in fox.SCHEMAS.items()}
            schemas["uareme.Estimate"] = self.writer.register_schema(
                "uareme.Estimate", "jsonschema", json.dumps(ESTIMATE_SCHEMA).encode())
            self.channels = {topic: self.writer.register_channel(topic, "json", schemas[name])
                             for topic, name in TOPICS.items()}
            self._flush()
        except OSError as exc:
            self._close_file()
            raise cannot_write(self.path, exc) from None

    def _open(self):
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            refuse_link(self.path)
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0), 0o666)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                refuse_link(self.path)
            raise cannot_write(self.path, exc) from None
        return os.fdopen(fd, "wb")

    def _message(self, topic: str, t_ns: int, message: dict) -> None:
        self.writer.add_message(self.channels[topic], log_time=max(t_ns, 0), data=fox.encode(message),
                                publish_time=max(t_ns, 0))

    def _flush(self) -> None:
        self.writer.flush()

    def _written(self, write) -> None:
        """Run `write()` (the messages of one result) and flush them as one chunk; a failing disk is an
        `OutputError` and the file keeps the chunks before it (no index)."""
        if self._file is None:
            raise OutputError(f"{self.path}: could not be written (an earlier write failed)")
        self._frame_start = self._file.tell()
        try:
            write()
            self._flush()
        except OSError as exc:
            self._index_ok = False
            self.undo_last()
            self._close_file()
            raise cannot_write(self.path, exc, "; kept its complete frames") from None

    def write(self, result: FrameResult) -> None:
        self._written(lambda: self._result(result))
        self.frames += 1

    def write_many(self, estimates: Estimates) -> None:
        def many():
            for k in range(len(estimates)):
                self._estimate(float(estimates.t_s[k]), estimates.R_wc[k], estimates.cov[k],
                               int(estimates.status[k]), None)
        self._written(many)
        self.frames += len(estimates)

    def _estimate(self, t_s: float, R_wc, cov, status: int, quality) -> int:
        t_ns = int(round(t_s * 1e9))
        self._message("/tf", t_ns, fox.frame_transform(t_ns, WORLD_FRAME_ID, CAMERA_FRAME_ID, quat_xyzw(R_wc)))
        self._message("/estimate", t_ns, estimate_message(t_s, R_wc, cov, status, quality))
        return t_ns

    def _result(self, result: FrameResult) -> None:
        est = result.estimate
        quality = None if result.visual is None else float(result.visual.quality)
        t_ns = self._estimate(result.t_s, est.R_wc, est.cov, int(est.status), quality)
        frame = result.frame
        if frame is None or frame.rgb is None:
            return
        height, width = frame.rgb.shape[:2]
        K, assumed = intrinsics_or_assumed(result.K, height, width, self.fov_deg)
        bgr = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)
        ok, jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            raise OutputError(f"{self.path}: OpenCV cannot encode frame {frame.index} as JPEG")
        self._message("/camera/image", t_ns, fox.compressed_image(t_ns, CAMERA_FRAME_ID, jpeg.tobytes()))
        self._message("/camera/calibration", t_ns, fox.camera_calibration(t_ns, CAMERA_FRAME_ID, K, height, width))
        self._message("/camera/annotations", t_ns, self._annotations(t_ns, est, K, assumed, height, width))

    def _annotations(self, t_ns: int, est, K: np.ndarray, assumed: bool, height: int, width: int) -> dict:
        thickness = max(2.0, min(height, width) / 160.0)
        points = [fox.lines(t_ns, up_arrow_px(est.up_c, K, height, width), UP_RGB, thickness)]
        horizon = horizon_segment(est.up_c, K, height, width)
        if horizon is not None:
            points.insert(0, fox.lines(t_ns, [horizon], HORIZON_RGB, thickness))
        roll, pitch = roll_pitch_deg(est.up_c)
        std = np.degrees(np.sqrt(np.clip(np.diag(est.cov), 0.0, None)))
        flags = status_flag_names(int(est.status)) or ["OK"]
        line = (f"roll {roll:.1f} pitch {pitch:.1f} deg, 1-sigma {max(std):.2f} deg, {'|'.join(flags)}"
                + ("" if horizon is not None else ", horizon out of view")
                + (f", {assumed_fov_note(self.fov_deg)}" if assumed else ""))
        font = max(10.0, height / 30.0)
        return {"circles": [], "points": points, "texts": [fox.text(t_ns, (4.0, font + 2.0), line, font)]}

    def undo_last(self) -> None:
        """Take back the last result (another output refused it): the file is cut back to before it
        and left without an index (readers then scan it, as after a crash)."""
        if self._file is None:
            return
        self._index_ok = False
        try:
            self._file.truncate(self._frame_start)
        except (OSError, ValueError):
            pass

    def _close_file(self) -> None:
        if self._file is not None:
            try:
                self._file.close()
            except OSError:
                pass
            self._file = None

    def close(self) -> None:
        if self._file is None:
            return
        try:
            if self._index_ok:
                self.writer.finish()
        except OSError as exc:
            raise cannot_write(self.path, exc, "; kept its complete frames (without an index)") from None
        finally:
            self._close_file()

    def summary(self) -> dict:
        """For summary.json: the MCAP file and how many results it holds."""
        return {"mcap": {"path": str(self.path), "frames": self.frames, "indexed": self._index_ok}}
