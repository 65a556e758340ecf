"""What every input source gives the pipeline: a time-ordered stream of frames and IMU batches.

A source opens its input in `__init__` (raising `InputError` naming the path and the problem when it
cannot), then `events()` yields `Frame` and `ImuBatch` objects in timestamp order: every IMU sample in
a batch is no later than the next frame's time. Mid-stream failures (a camera disconnecting, a video
that stops decoding) raise `SourceError`. Sources hold at most a few frames in memory.

Conventions: times are float seconds on the source's clock; IMU samples are in the IMU frame `i`
(gyro rad/s, specific force m/s^2); `R_ci` maps IMU to camera coordinates.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from uareme_fusion.types import Frame, ImuBatch  # noqa: F401  (sources yield ImuBatch)


@dataclass(frozen=True)
class GroundTruth:
    """Reference camera attitudes `R_wc` (N, 3, 3) at times `t_s` (N,), world z up where the dataset
    says so (otherwise evaluation aligns a constant rotation)."""

    t_s: np.ndarray
    R_wc: np.ndarray
    gravity_aligned: bool = False
    """True when the reference world frame has z up (simulator, TUM with IMU, EuRoC)."""

    def at(self, t_s: np.ndarray, max_gap_s: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
        """`R_wc` slerped at `t_s` and a mask of the times within `max_gap_s` of a reference sample
        and inside its span (outside the mask the rotation is the nearest sample's)."""
        t_s = np.asarray(t_s, dtype=float)
        t_clip = np.clip(t_s, self.t_s[0], self.t_s[-1])
        if len(self.t_s) == 1:
            R = np.repeat(self.R_wc[:1], len(t_s), axis=0)
        else:
            R = Slerp(self.t_s, Rotation.from_matrix(self.R_wc))(t_clip).as_matrix()
        idx = np.clip(np.searchsorted(self.t_s, t_s), 1, max(len(self.t_s) - 1, 1))
        gap = np.minimum(np.abs(t_s - self.t_s[idx - 1]), np.abs(t_s - self.t_s[np.minimum(idx, len(self.t_s) - 1)]))
        ok = (t_s >= self.t_s[0] - max_gap_s) & (t_s <= self.t_s[-1] + max_gap_s) & (gap <= max_gap_s)
        return R, ok


PLATFORMS = ("building", "handheld", "vehicle")
"""What may carry a camera (`SourceInfo.platform`); each is also the name of a camera EKF preset."""


@dataclass(frozen=True)
class SourceInfo:
    """What a source knows about itself before it runs."""

    name: str
    """What the user passed (a path, `oak`, `webcam:0`, `sim:bus`), for messages and summaries."""
    n_frames: int | None = None
    """Number of frames when known (files, datasets); None for live cameras."""
    fps: float | None = None
    K: np.ndarray | None = None
    """(3, 3) intrinsics in pixels of the frames as yielded (OpenCV convention), None when unknown."""
    K_origin: str | None = None
    """Where K came from (--intrinsics, a camera file, published dataset values, scene.json), for summaries."""
    has_frames: bool = True
    """False for IMU-only sources (BROAD, an IMU CSV): the pipeline then reports one estimate per IMU
    batch, so such sources should yield batches at about the rate estimates are wanted (e.g. 30 Hz)."""
    has_depth: bool = False
    has_imu: bool = False
    R_ci: np.ndarray = field(default_factory=lambda: np.eye(3))
    """IMU-to-camera rotation (device calibration for OAK; identity unless configured)."""
    imu_time_offset_s: float = 0.0
    """Added to IMU timestamps to put them on the camera clock."""
    image_size: tuple[int, int] | None = None
    """(height, width) of yielded frames when known."""
    depth_rendered: bool = False
    """True when the depth maps are rendered (ICL-NUIM, the simulator) rather than measured: their noise
    is per pixel, with no plane-wide part (a real sensor's calibration tilts whole planes), so depth
    normals count one independent error per fit window (`normals.depth.depth_normals_for`)."""
    gt_time_offset_s: float = 0.0
    """Seconds the source added to its ground truth's stamps to put them on the camera clock (a dataset
    default: TUM RGB-D, `formats.tum.TUM_RGBD_GT_TIME_OFFSET_S`); `--gt-time-offset-s` replaces it."""
    platform: str | None = None
    """What carries the camera when the source says so (`handheld`, `vehicle`, `building`: scene.json or
    source.json `platform`); the EKF preset when none is asked for. None: unknown."""


def spread_indices(count: int, n: int, limit: int | None = None) -> list[int]:
    """Up to `n` indices spread evenly over `range(count)` (over its first `limit` when given), first and
    last included."""
    count = count if limit is None else min(count, limit)
    return np.unique(np.linspace(0, count - 1, min(n, count)).round().astype(int)).tolist() if count > 0 else []


class Source(ABC):
    """A stream of `Frame` and `ImuBatch` events in timestamp order. Use as a context manager."""

    info: SourceInfo
    notes: list[str]
    """What the driver left out or did not use (printed and put in summary.json); sources set it."""
    fixes: list[str]
    """Automatic repairs of the input (e.g. IMU units), printed as warnings and put in summary.json."""

    def sample_frames(self, n: int, limit: int | None = None) -> list[Frame] | None:
        """Up to `n` frames spread evenly over a recording (over its first `limit` frames when given: a
        run that stops there), read apart from the stream (`events` is left as it is), for what is best
        known before the stream runs (the camera's K from the scene); frames that do not decode are left
        out (the stream reports them). None where the source cannot: a live camera, a source read once.
        None unless a source says otherwise."""
        return None

    @abstractmethod
    def events(self) -> Iterator[Frame | ImuBatch]:
        """Yield frames and IMU batches in timestamp order; raise `SourceError` if the input fails
        mid-stream."""

    def ground_truth(self) -> GroundTruth | None:
        """Reference attitudes when the dataset has them."""
        return None

    def close(self) -> None:
        """Release files, decoders and devices. Safe to call twice."""

    def report(self) -> tuple[list[str], list[str]]:
        """(notes, fixes) of this source, empty lists where a driver sets none."""
        return list(getattr(self, "notes", [])), list(getattr(self, "fixes", []))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
