"""Luxonis OAK cameras through depthai v3: RGB, IMU and optional stereo depth aligned to RGB.

    with OakSource() as src: ...                    # first device found (`oak`)
    with OakSource("1844301011F4C51200", depth=True, fps=30, size=(640, 400)) as src: ...   # `oak:ID`

depthai is an optional extra (`pip install uareme-fusion[oak]`), imported only when a device is
opened. The device-facing part (`OakSource`) is thin; everything that can be wrong without hardware
is pure and tested with fake messages:
- `frame_from_messages`: ImgFrame (+ depth ImgFrame) -> `Frame` (RGB uint8, depth metres from the
  uint16 millimetres, device timestamp in seconds, K from the calibration);
- `batch_from_packets`: IMUPacket list -> `ImuBatch` (gyro rad/s, accel m/s^2 as the IMU frame
  reports them, stamped with the gyro report's device time; repeated stamps dropped and counted);
- `FrameImuSync`: holds each frame until the IMU has reached its time, so the stream is in time
  order with every sample before the frame it precedes;
- `rotation_from_extrinsics`: the calibration's IMU-to-camera 4x4 (translation in cm) -> `R_ci`.
Clocks: frames and IMU both carry the device clock (`getTimestampDevice`), so
`imu_time_offset_s` is 0. A device that stops delivering raises `SourceError`; `--record` works
through `drivers.recorder.record` like any source.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import cv2
import numpy as np

from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.rotations import is_rotation, project_to_so3
from uareme_fusion.types import Frame, ImuBatch

from .base import Source, SourceInfo
from .interleave import release_until

OAK_DEPTH_UNITS_PER_M = 1000.0
"""OAK stereo depth is uint16 millimetres."""
EXTRINSICS_TRANSLATION_UNIT_M = 0.01
"""depthai calibration extrinsics hold translations in centimetres."""
MAX_PENDING_FRAMES = 3
"""Frames held waiting for the IMU before they are released anyway (IMU stalled or slower)."""
QUEUE_TIMEOUT_S = 2.0
"""No message for this long from a running device counts as a disconnect."""


def import_depthai():
    """The depthai module, or an `InputError` saying how to install it."""
    try:
        import depthai
    except ImportError:
        raise InputError("OAK cameras need depthai: install uareme-fusion[oak] (pip install 'depthai>=3')") from None
    return depthai


def timestamp_s(stamp) -> float:
    """A depthai timestamp (datetime.timedelta since device boot) in float seconds."""
    return float(stamp.total_seconds())


def frame_from_messages(rgb_msg, index: int, K: np.ndarray | None = None, depth_msg=None,
                        depth_units_per_m: float = OAK_DEPTH_UNITS_PER_M) -> Frame:
    """An RGB ImgFrame (BGR from `getCvFrame`) and an optional depth ImgFrame aligned to it
    (uint16 from `getFrame`, 0 = no depth) as a `Frame` at the RGB device time."""
    bgr = np.asarray(rgb_msg.getCvFrame())
    if bgr.ndim == 2:
        rgb = cv2.cvtColor(bgr, cv2.COLOR_GRAY2RGB)
    else:
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    depth = None
    if depth_msg is not None:
        raw = np.asarray(depth_msg.getFrame())
        if raw.shape[:2] != rgb.shape[:2]:
            raise SourceError(f"oak: depth of size {raw.shape[:2]} is not aligned to RGB of size {rgb.shape[:2]}")
        depth = raw.astype(np.float32) / np.float32(depth_units_per_m)  # as the TUM reader divides: replays match
    return Frame(t_s=timestamp_s(rgb_msg.getTimestampDevice()), rgb=rgb, depth=depth, K=K, index=index)


@dataclass
class ImuConversionCounts:
    repeated: int = 0
    """Packets whose gyro stamp repeats the previous one (an accelerometer-only update), dropped."""


def batch_from_packets(packets: Iterable, counts: ImuConversionCounts | None = None,
                       last_t_s: float = -np.inf) -> ImuBatch:
    """IMUPackets (`.gyroscope`, `.acceleroMeter` with x, y, z and `getTimestampDevice()`) as an
    `ImuBatch` stamped with the gyro times; packets not newer than `last_t_s` or the previous one
    are dropped and counted in `counts.repeated`."""
    rows, times = [], []
    for packet in packets:
        g, a = packet.gyroscope, packet.acceleroMeter
        t = timestamp_s(g.getTimestampDevice())
        if t <= last_t_s:
            if counts is not None:
                counts.repeated += 1
            continue
        last_t_s = t
        times.append(t)
        rows.append((g.x, g.y, g.z, a.x, a.y, a.z))
    if not rows:
        return ImuBatch.empty()
    values = np.asarray(rows, float)
    return ImuBatch(np.asarray(times, float), values[:, :3], values[:, 3:])


def rotation_from_extrinsics(T, what: str = "IMU-to-camera extrinsics") -> np.ndarray:
    """`R_ci` (3, 3) from depthai's `getImuToCameraExtrinsics` (4x4 list, translation in cm):
    maps IMU coordinates to camera coordinates; `InputError` when it is no rotation (uncalibrated)."""
    T = np.asarray(T, float)
    if T.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(T)):
        raise InputError(f"oak: {what} must be a 4x4 matrix, got shape {T.shape}")
    R = T[:3, :3]
    if not is_rotation(R, atol=1e-3):
        raise InputError(f"oak: {what} hold no rotation (device not IMU-calibrated?): {R.round(4).tolist()}")
    return project_to_so3(R)


@dataclass
class FrameImuSync:
    """Orders frames and IMU batches from two device queues into one time-ordered stream.

    `push_imu` / `push_frame` return the events now ready. A frame is released once an IMU sample
    later than it has arrived (so every sample up to the frame time precedes it), or when more than
    `max_pending_frames` are waiting (the IMU stalled). IMU samples that arrive after a frame later
    than them was released are dropped and counted in `late_imu` (they would break time order).
    Without an IMU (`use_imu` False) frames pass straight through.
    """

    use_imu: bool = True
    max_pending_frames: int = MAX_PENDING_FRAMES
    late_imu: int = 0
    _frames: deque = field(default_factory=deque)
    _imu: list = field(default_factory=list)
    _released_t_s: float = -np.inf

    def push_imu(self, batch: ImuBatch) -> list:
        if len(batch):
            late = batch.t_s <= self._released_t_s
            if late.any():
                self.late_imu += int(late.sum())
                keep = np.flatnonzero(~late)
                batch = batch[keep]
            if len(batch):
                self._imu.append(batch)
        return self._release()

    def push_frame(self, frame: Frame) -> list:
        if not self.use_imu:
            self._released_t_s = max(self._released_t_s, frame.t_s)
            return [frame]
        self._frames.append(frame)
        return self._release()

    def _newest_imu_s(self) -> float:
        return self._imu[-1].t_s[-1] if self._imu else -np.inf

    def _release(self, force: bool = False) -> list:
        out = []
        while self._frames and (force or self._newest_imu_s() > self._frames[0].t_s
                                or len(self._frames) > self.max_pending_frames):
            frame = self._frames.popleft()
            released, self._imu = release_until(self._imu, frame.t_s)
            if released is not None:
                out.append(released)
            out.append(frame)
            self._released_t_s = max(self._released_t_s, frame.t_s)
        return out

    def flush(self) -> list:
        """Everything still held, in order (end of stream)."""
        out = self._release(force=True)
        out.extend(self._imu)
        self._imu = []
        return out


class OakSource(Source):
    """A live OAK camera; see the module docstring. `size` (width, height) of the RGB stream,
    `fps`, `depth` (stereo depth aligned to RGB), `imu_rate_hz` (0: no IMU)."""

    def __init__(self, device_id: str | None = None, fps: float | None = None, size: tuple[int, int] = (640, 400),
                 depth: bool = False, imu_rate_hz: float = 200.0):
        dai = import_depthai()
        self.dai, self.fps = dai, float(fps or 30.0)
        self.width, self.height = (int(v) for v in size)
        self.depth, self.use_imu = bool(depth), imu_rate_hz > 0
        name = "oak" if device_id is None else f"oak:{device_id}"
        try:
            device = dai.Device(dai.DeviceInfo(device_id)) if device_id else dai.Device()
        except RuntimeError as exc:
            raise InputError(f"{name}: cannot connect to an OAK device ({exc})") from None
        self.pipeline = dai.Pipeline(device)
        calib = device.readCalibration()
        cam_a = dai.CameraBoardSocket.CAM_A
        K = np.asarray(calib.getCameraIntrinsics(cam_a, self.width, self.height), float)
        R_ci = np.eye(3)
        if self.use_imu:
            R_ci = rotation_from_extrinsics(calib.getImuToCameraExtrinsics(cam_a, True))
        self._queues = self._build(dai, device, imu_rate_hz)
        self.sync = FrameImuSync(use_imu=self.use_imu)
        self.imu_counts = ImuConversionCounts()
        self.info = SourceInfo(name=name, n_frames=None, fps=self.fps, K=K, K_origin="OAK device calibration",
                               has_depth=self.depth, has_imu=self.use_imu, R_ci=R_ci, image_size=(self.height, self.width))
        self.notes: list[str] = []
        self._started = False

    def _build(self, dai, device, imu_rate_hz: float) -> dict:
        p = self.pipeline
        color = p.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
        rgb_out = color.requestOutput((self.width, self.height), dai.ImgFrame.Type.BGR888i, fps=self.fps)
        queues = {}
        if self.depth:
            left = p.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_B)
            right = p.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_C)
            stereo = p.create(dai.node.StereoDepth)
            left.requestOutput((640, 400), fps=self.fps).link(stereo.left)
            right.requestOutput((640, 400), fps=self.fps).link(stereo.right)
            sync = p.create(dai.node.Sync)
            if device.getPlatform() == dai.Platform.RVC4:
                align = p.create(dai.node.ImageAlign)
                stereo.depth.link(align.input)
                rgb_out.link(align.inputAlignTo)
                align.outputAligned.link(sync.inputs["depth"])
            else:
                rgb_out.link(stereo.inputAlignTo)
                stereo.depth.link(sync.inputs["depth"])
            rgb_out.link(sync.inputs["rgb"])
            queues["frames"] = sync.out.createOutputQueue(maxSize=4, blocking=False)
        else:
            queues["frames"] = rgb_out.createOutputQueue(maxSize=4, blocking=False)
        if self.use_imu:
            imu = p.create(dai.node.IMU)
            imu.enableIMUSensor([dai.IMUSensor.ACCELEROMETER_RAW, dai.IMUSensor.GYROSCOPE_RAW], int(imu_rate_hz))
            imu.setBatchReportThreshold(5)
            imu.setMaxBatchReports(20)
            queues["imu"] = imu.out.createOutputQueue(maxSize=50, blocking=False)
        return queues

    def _messages(self) -> Iterator[tuple[str, object]]:
        """(kind, message) pairs from the device queues; `SourceError` when the device goes away."""
        import time

        last = time.monotonic()
        while True:
            got = False
            try:
                if not self.pipeline.isRunning():
                    raise RuntimeError("pipeline stopped")
                for kind, queue in self._queues.items():
                    msg = queue.tryGet()
                    if msg is not None:
                        got = True
                        yield kind, msg
            except RuntimeError as exc:
                raise SourceError(f"{self.info.name}: device disconnected ({exc})") from None
            now = time.monotonic()
            if got:
                last = now
            elif now - last > QUEUE_TIMEOUT_S:
                raise SourceError(f"{self.info.name}: no data for {QUEUE_TIMEOUT_S:g} s (device disconnected?)")
            else:
                time.sleep(0.001)

    def events(self) -> Iterator[Frame | ImuBatch]:
        if not self._started:
            self.pipeline.start()
            self._started = True
        index, last_imu_t = 0, -np.inf
        for kind, msg in self._messages():
            if kind == "imu":
                batch = batch_from_packets(msg.packets, self.imu_counts, last_imu_t)
                if len(batch):
                    last_imu_t = float(batch.t_s[-1])
                ready = self.sync.push_imu(batch)
            else:
                rgb_msg, depth_msg = (msg["rgb"], msg["depth"]) if self.depth else (msg, None)
                ready = self.sync.push_frame(frame_from_messages(rgb_msg, index, self.info.K, depth_msg))
                index += 1
            yield from ready

    def close(self) -> None:
        pipeline, self.pipeline = getattr(self, "pipeline", None), None
        if pipeline is not None and self._started:
            pipeline.stop()
