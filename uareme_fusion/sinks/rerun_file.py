"""A run logged to a rerun recording (`--rerun FILE.rrd`; open it with `rerun FILE.rrd`).

Needs `rerun-sdk` (the `viewer` extra: `pip install "uareme-fusion[viewer]"`). Entities, all on the
`time` timeline (the frame's time, seconds):
- `world`: z up (`ViewCoordinates.RIGHT_HAND_Z_UP`); `world/camera`: the estimated `R_wc` as a
  rotation (camera OpenCV axes, `ViewCoordinates.RDF`), a pinhole with the frame's K (or the one
  assumed from `fov_deg`), and under it `image` (horizon and Manhattan axes drawn), `normals`
  (X-Y-Z as R-G-B) and `confidence` (kappa, white = 75);
- `plots/roll_deg`, `plots/pitch_deg` (from the estimated up vector), `plots/std_deg/{x,y,z}` (square
  roots of the covariance's diagonal, camera axes), `plots/status` (the `Status` flags as an integer)
  and `status` (a text line each time the flags change).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.safe_files import cannot_write
from ..io.normal_maps import normals_to_rgb
from ..overlay import confidence_to_rgb, intrinsics_or_assumed
from ..rotations import quat_xyzw
from ..types import FrameResult, Status
from .drawing import overlay_image

APPLICATION_ID = "uareme-fusion"


def roll_pitch_deg(up_c: np.ndarray) -> tuple[float, float]:
    """Camera roll (image rotation, positive clockwise as seen) and pitch (positive looking up),
    degrees, from world up in the OpenCV camera frame; (0, 0) for a level camera (`up_c = (0, -1, 0)`)."""
    up = np.asarray(up_c, float) / np.linalg.norm(up_c)
    return float(np.degrees(np.arctan2(up[0], -up[1]))), float(np.degrees(np.arcsin(np.clip(up[2], -1.0, 1.0))))


def _os_error(exc: RuntimeError) -> OSError:
    """The `OSError` inside a rerun SDK error message (errno and reason), for `cannot_write`."""
    found = re.search(r"os error (\d+)", str(exc))
    if found is None:
        return OSError(str(exc).split(", path:")[0])
    code = int(found.group(1))
    return OSError(code, os.strerror(code))


def _rerun():
    try:
        import rerun as rr
    except ImportError:
        raise InputError("--rerun needs the rerun SDK: pip install 'uareme-fusion[viewer]' (or rerun-sdk)") from None
    return rr


class RerunSink:
    """Logs every result to a `.rrd` file; see the module docstring."""

    def __init__(self, path: str | Path, fov_deg: float = 60.0):
        rr = _rerun()
        self.path, self.fov_deg, self.rr = Path(path), float(fov_deg), rr
        if self.path.suffix.lower() != ".rrd":
            raise InputError(f"--rerun {self.path}: a rerun recording is a .rrd file")
        self.rec = rr.RecordingStream(APPLICATION_ID)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(str(self.path))
        except OSError as exc:
            raise cannot_write(self.path, exc) from None
        except RuntimeError as exc:  # the SDK's own: "Failed to create file: <reason> (os error N), path: ..."
            raise cannot_write(self.path, _os_error(exc)) from None
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._pinhole_size = None
        self._status = None

    def write(self, result: FrameResult) -> None:
        rr, rec, est = self.rr, self.rec, result.estimate
        rec.set_time("time", duration=float(result.t_s))
        rec.log("world/camera", rr.Transform3D(quaternion=rr.Quaternion(xyzw=quat_xyzw(est.R_wc))))
        roll, pitch = roll_pitch_deg(est.up_c)
        rec.log("plots/roll_deg", rr.Scalars(roll))
        rec.log("plots/pitch_deg", rr.Scalars(pitch))
        std_deg = np.degrees(np.sqrt(np.clip(np.diag(est.cov), 0.0, None)))
        for axis, value in zip("xyz", std_deg):
            rec.log(f"plots/std_deg/{axis}", rr.Scalars(float(value)))
        rec.log("plots/status", rr.Scalars(float(int(est.status))))
        if est.status != self._status:
            names = [flag.name for flag in Status if flag and flag in est.status] or ["OK"]
            rec.log("status", rr.TextLog(", ".join(names)))
            self._status = est.status
        frame = result.frame
        if frame is not None and frame.rgb is not None:
            self._log_images(result)

    def _log_images(self, result: FrameResult) -> None:
        rr, rec, frame = self.rr, self.rec, result.frame
        height, width = frame.rgb.shape[:2]
        if self._pinhole_size != (width, height):
            K, _ = intrinsics_or_assumed(frame.K, height, width, self.fov_deg)
            rec.log("world/camera", rr.Pinhole(image_from_camera=K, resolution=[width, height],
                                               camera_xyz=rr.ViewCoordinates.RDF))
            self._pinhole_size = (width, height)
        rec.log("world/camera/image", rr.Image(overlay_image(result, self.fov_deg, panes=False)))
        if result.normal_map is not None:
            rec.log("world/camera/normals", rr.Image(normals_to_rgb(result.normal_map.normals)))
            rec.log("world/camera/confidence", rr.Image(confidence_to_rgb(result.normal_map.kappa)))

    def close(self) -> None:
        if self.rec is not None:
            self.rec.flush()
            self.rec.disconnect()
            self.rec = None
