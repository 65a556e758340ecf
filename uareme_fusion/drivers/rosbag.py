"""ROS bags as a `Source`: a ROS 1 `.bag`, a ROS 2 bag folder (`metadata.yaml` with `.db3` or `.mcap`
files) and a bare `.mcap` (or `.db3`), read with `rosbags` (the `ros` extra).

    with RosbagSource("drive.bag") as src: ...
    with RosbagSource("rosbag2_2024_05_01/", image_topic="/cam/image_raw/compressed") as src: ...

Topics are found by message type (`bag_topics.choose_topics`; options `image_topic`, `depth_topic`,
`camera_info_topic`, `imu_topic`, `gt_topic` choose among several; `camera`, the `--intrinsics`,
replaces the CameraInfo). Messages are converted by
`formats.ros_messages`: images to RGB uint8, depth to metres, the first CameraInfo to K and
distortion, used as given (frames are undistorted with them and carry K; `info.K_origin` names the
bag and topic), IMU messages to gyro rad/s and specific force m/s^2 (orientation unused), checked for
unit and ordering mistakes as IMU tables are (`imu_checks.check_imu_log`).

Times: header stamps (float seconds of sec + nanosec), not the bag's receive times; a topic whose
header stamps are all zero (a driver that never set them) is read at its receive times, with a fix
line saying so. Frames whose stamp does not increase are left out (a note counts them). Depth is
paired with the image of the nearest stamp within `max_dt_s`. Clocks: the image and IMU stamps must
overlap (as an IMU log merged into a video, `imu_csv.spans_overlap`); when they do not and the
receive times do line them up, the IMU goes on the camera clock with the offset of the two topics'
median header-minus-receive times (`info.imu_time_offset_s`, a fix line; `--imu-time-offset-s`
overrides it); otherwise the run is refused when the first frame arrives, naming both topics.

Frames: `R_ci` comes from `/tf_static` when its static transforms join the image's and the IMU's
`frame_id` (`bag_tf.static_rotation`), else it is the identity (a note says which; `--imu-rotation`
replaces it); the IMU's `frame_id` is in the notes.
Ground truth (`ground_truth()`): a PoseStamped, PoseWithCovarianceStamped or Odometry topic taken as
the attitude of the IMU body, so `R_wc = R_wb @ R_ci^T` (the camera's own attitude when R_ci is the
identity, as for a bag without IMU); its world is z up (gravity-aligned) when the header's frame_id
is one of `Z_UP_FRAMES` (REP 103 / REP 105), otherwise evaluation aligns a constant rotation.
A bag without an image topic is an IMU-only source (batches of `IMU_ONLY_BATCH_S`).
"""

from __future__ import annotations

import dataclasses
from collections import deque
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.types import Frame, ImuBatch

from ..formats import ros_messages as ros
from ..formats.euroc import EurocImu
from ..formats.tum import associate
from .bag_tf import TF_STATIC_TOPIC, static_rotation
from .bag_topics import BagTopics, choose, choose_topics
from .base import GroundTruth, Source, SourceInfo, spread_indices
from .imu_checks import check_imu_log
from .imu_csv import non_increasing_note, spans_overlap
from .interleave import IMU_ONLY_BATCH_S, interleave, split_by_span
from .intrinsics import CameraModel, Undistorter, check_camera

BAG_SUFFIXES = (".bag", ".mcap", ".db3")
METADATA = "metadata.yaml"
NS_PER_S = 1_000_000_000
SHOWN_UNUSED = 5
Z_UP_FRAMES = ("map", "odom", "world", "earth", "enu")
"""Pose frame_ids whose z axis is up by ROS convention (REP 103 ENU, REP 105 map / odom / earth)."""


def is_bag(path: Path) -> bool:
    """True for a ROS 2 bag folder (holding metadata.yaml) or a file named .bag, .mcap or .db3."""
    return (path.is_dir() and (path / METADATA).is_file()) or (path.is_file() and path.suffix.lower() in BAG_SUFFIXES)


def _any_reader(path: Path):
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InputError(f"{path}: reading ROS bags and MCAP files needs rosbags: pip install "
                         "'uareme-fusion[ros]'") from None
    return AnyReader([path], default_typestore=get_typestore(Stores.LATEST))


@dataclasses.dataclass
class _Stamps:
    """Header and receive times (int ns) of a topic's messages, in bag order."""

    header_ns: list = dataclasses.field(default_factory=list)
    receive_ns: list = dataclasses.field(default_factory=list)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.header_ns, np.int64), np.asarray(self.receive_ns, np.int64)


class RosbagSource(Source):
    """A ROS 1 or ROS 2 bag (or bare MCAP); see the module docstring."""

    def __init__(self, path: str | Path, image_topic: str | None = None, imu_topic: str | None = None,
                 depth_topic: str | None = None, camera_info_topic: str | None = None,
                 gt_topic: str | None = None, use_imu: bool = True, max_dt_s: float = 0.02,
                 camera: CameraModel | None = None):
        self.path = Path(path)
        self.where = str(path)
        self.notes: list[str] = []
        self.fixes: list[str] = []
        self._given_camera = camera
        self._undistorter: Undistorter | None = None
        self.reader = _any_reader(self.path)
        try:
            self.reader.open()
        except Exception as exc:  # rosbags raises its own errors, KeyError and struct errors on bad files
            raise InputError(f"{self.where}: not a ROS bag rosbags can read ({type(exc).__name__}: {exc})") from None
        try:
            self._open(image_topic, imu_topic, depth_topic, camera_info_topic, gt_topic, use_imu, max_dt_s)
        except BaseException:
            self.close()
            raise

    def _open(self, image_topic, imu_topic, depth_topic, camera_info_topic, gt_topic, use_imu, max_dt_s) -> None:
        self.topics: BagTopics = choose_topics(self.reader, self.where, image_topic=image_topic, imu_topic=imu_topic,
                                               depth_topic=depth_topic, camera_info_topic=camera_info_topic,
                                               gt_topic=gt_topic)
        if not use_imu:
            self.topics = dataclasses.replace(self.topics, imu=None)
        if self.topics.image is None and self.topics.imu is None:
            found = ", ".join(f"{t} ({m})" for t, m in list(self.topics.unused.items())[:SHOWN_UNUSED]) or "none"
            raise InputError(f"{self.where}: no sensor_msgs/Image, CompressedImage or Imu topic (topics: {found})")
        self._index(max_dt_s)
        if self.n_frames == 0 and self.imu is None:
            empty = self.topics.image or self.topics.imu
            raise InputError(f"{self.where}: {empty} holds no messages (nothing to run on)")
        R_ci = self._imu_rotation()
        self._note_unused()
        has_frames = self.n_frames > 0
        fps = float(NS_PER_S / np.median(np.diff(self.frame_ns))) if self.n_frames > 1 else None
        self.info = SourceInfo(name=self.where, n_frames=self.n_frames, fps=fps,
                               K=None if self.camera is None else self.camera.K,
                               K_origin=None if self.camera is None else self.camera.origin,
                               has_frames=has_frames, has_depth=self._depth_of is not None and bool(self._depth_of),
                               has_imu=self.imu is not None, image_size=self._size, R_ci=R_ci,
                               imu_time_offset_s=self._clock_fix_s())

    # The first pass: stamps of every image and depth message, the IMU, the first CameraInfo, the poses.

    def _connections(self, topic: str | None) -> list:
        return [] if topic is None else [c for c in self.reader.connections if c.topic == topic]

    def _index(self, max_dt_s: float) -> None:
        t = self.topics
        roles = {t.image: "image", t.depth: "depth", t.camera_info: "camera_info", t.imu: "imu", t.pose: "pose"}
        roles.pop(None, None)
        stamps = {"image": _Stamps(), "depth": _Stamps()}
        imu_rows, imu_stamps, pose_rows, pose_ns = [], _Stamps(), [], []
        self._pose_frame_id = None
        self._info_msg = self._first_image = None
        self.imu_frame_id = None
        conns = [c for topic in roles for c in self._connections(topic)]
        for connection, receive_ns, raw in self.reader.messages(connections=conns):
            role = roles[connection.topic]
            if role == "camera_info" and self._info_msg is not None:
                continue
            if role in stamps:  # images: only their stamps now (the stream deserialises them)
                if role == "image" and self._first_image is None:
                    self._first_image = self._deserialize(raw, connection)
                stamps[role].header_ns.append(ros.raw_stamp_ns(raw, self.reader.is2))
                stamps[role].receive_ns.append(receive_ns)
                continue
            msg = self._deserialize(raw, connection)
            if role == "imu":
                imu_stamps.header_ns.append(ros.stamp_ns(msg.header))
                imu_stamps.receive_ns.append(receive_ns)
                imu_rows.append((*ros.vector3(msg.angular_velocity), *ros.vector3(msg.linear_acceleration)))
                self.imu_frame_id = self.imu_frame_id or msg.header.frame_id
            elif role == "pose":
                pose_ns.append(ros.stamp_ns(msg.header))
                self._pose_frame_id = self._pose_frame_id or msg.header.frame_id
                pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
                pose_rows.append(ros.quaternion_xyzw(pose.orientation))
            else:
                self._info_msg = msg
        self._frames_index(stamps["image"], stamps["depth"], max_dt_s)
        self._imu(imu_stamps, np.asarray(imu_rows, float).reshape(-1, 6))
        self._poses = (np.asarray(pose_ns, np.int64), np.asarray(pose_rows, float).reshape(-1, 4))
        self.camera = self._camera()

    def _deserialize(self, raw, connection):
        try:
            return self.reader.deserialize(raw, connection.msgtype)
        except Exception as exc:
            raise InputError(f"{self.where}: a {connection.msgtype} message on {connection.topic} does not "
                             f"deserialise ({exc})") from None

    def _header_times(self, stamps: _Stamps, topic: str) -> np.ndarray:
        header_ns, receive_ns = stamps.arrays()
        if len(header_ns) and not header_ns.any():
            self.fixes.append(f"{self.where}: {topic}: every header stamp is zero (never set): read at the bag's "
                              "receive times instead")
            return receive_ns
        return header_ns

    def _frames_index(self, image: _Stamps, depth: _Stamps, max_dt_s: float) -> None:
        t_ns = self._header_times(image, self.topics.image or "")
        self._image_receive_ns = image.arrays()[1]
        keep = np.ones(len(t_ns), bool)
        if len(t_ns) > 1:
            newest_before = np.maximum.accumulate(np.r_[np.iinfo(np.int64).min, t_ns[:-1]])
            keep = t_ns > newest_before
        if not keep.all():
            self.notes.append(f"{self.where}: {self.topics.image}: {int((~keep).sum())} images whose header stamp "
                              "is not after an earlier image's were left out")
        self._kept = np.flatnonzero(keep)  # bag-order index of each yielded frame
        self.frame_ns = t_ns[keep]
        self.n_frames = len(self.frame_ns)
        self._depth_of: dict[int, int] | None = None
        self._depth_receive_ns = depth.arrays()[1]
        self._depth_ns = np.zeros(0, np.int64)
        if self.topics.depth is not None and self.n_frames:
            self._depth_ns = self._header_times(depth, self.topics.depth)
            order = np.argsort(self._depth_ns, kind="stable")
            ia, ib = associate(self.frame_ns * 1e-9, self._depth_ns[order] * 1e-9, max_dt_s)
            self._depth_of = {int(self._kept[i]): int(order[j]) for i, j in zip(ia, ib)}
            unpaired = self.n_frames - len(ia)
            if unpaired:
                self.notes.append(f"{self.where}: {unpaired} images have no depth on {self.topics.depth} within "
                                  f"{max_dt_s} s (yielded without depth)")
        self._size = None
        if self._first_image is not None:
            self._size = ros.image_rgb(self._first_image, self._where_message(self.topics.image)).shape[:2]

    def _imu(self, stamps: _Stamps, rows: np.ndarray) -> None:
        self.imu = None
        if self.topics.imu is None or not len(rows):
            if self.topics.imu is not None:
                self.notes.append(f"{self.where}: {self.topics.imu} holds no messages: no IMU")
            return
        t_ns = self._header_times(stamps, self.topics.imu)
        self._imu_receive_ns = stamps.arrays()[1]
        order = np.argsort(t_ns, kind="stable")
        raw = EurocImu(Path(f"{self.where} {self.topics.imu}"), t_ns[order], t_ns[order] * 1e-9,
                       rows[order, :3], rows[order, 3:])
        self.imu, fixes = check_imu_log(raw)
        self.fixes += fixes
        self.notes += non_increasing_note(self.imu)
        self._imu_raw_ns = (t_ns, self._imu_receive_ns)
        self.notes.append(f"{self.where}: IMU from {self.topics.imu}: frame_id {self.imu_frame_id!r}, "
                          f"{len(self.imu.t_s)} samples at {self.imu.rate_hz:.4g} Hz")

    def _imu_rotation(self) -> np.ndarray:
        """R_ci from /tf_static between the image's and the IMU's frame_id, else the identity (noted)."""
        self._tf_used = False
        if self.imu is None or self._first_image is None:
            return np.eye(3)
        camera_frame = self._first_image.header.frame_id
        R_ci = static_rotation(self.reader, camera_frame, self.imu_frame_id)
        if R_ci is None:
            self.notes.append(f"{self.where}: R_ci (camera from IMU) is the identity: no {TF_STATIC_TOPIC} chain joins "
                              f"the camera's frame_id {camera_frame!r} and the IMU's {self.imu_frame_id!r} "
                              "(--imu-rotation gives it)")
            return np.eye(3)
        self._tf_used = True
        self.notes.append(f"{self.where}: R_ci (camera from IMU) from {TF_STATIC_TOPIC}, {camera_frame!r} <- "
                          f"{self.imu_frame_id!r}: {np.round(R_ci, 4).tolist()}")
        return R_ci

    def _camera(self) -> CameraModel | None:
        """The given camera (`--intrinsics`: it replaces the CameraInfo, on the bag's raw frames), else the
        first CameraInfo's, else None."""
        if self._given_camera is not None:
            if self._info_msg is not None:
                self.notes.append(f"{self._given_camera.origin} replaces the bag's {self.topics.camera_info} "
                                  "(sensor_msgs/CameraInfo)")
            return check_camera(self._given_camera, self._given_camera.origin, self._size)
        if self._info_msg is None:
            if self.n_frames:
                self.notes.append(f"{self.where}: no sensor_msgs/CameraInfo topic: intrinsics unknown")
            return None
        where = f"{self.where} {self.topics.camera_info} (sensor_msgs/CameraInfo)"
        K, dist, model, size = ros.camera_info_fields(self._info_msg, where)
        if size is not None and self._size is not None and size != self._size:
            raise InputError(f"{where}: is for {size[1]}x{size[0]} images, and {self.topics.image} holds "
                             f"{self._size[1]}x{self._size[0]} images")
        camera = CameraModel(K, dist, model, where, image_size=size or self._size)
        return check_camera(camera, where, self._size)

    def _note_unused(self) -> None:
        unused = dict(self.topics.unused)
        if self._tf_used:
            unused.pop(TF_STATIC_TOPIC, None)
        for role, candidates in self.topics.candidates.items():
            unused.update({t: m for t, m in candidates.items() if t != getattr(self.topics, role)})
        if unused:
            shown = ", ".join(f"{t} ({m.replace('/msg/', '/')})" for t, m in list(unused.items())[:SHOWN_UNUSED])
            more = len(unused) - SHOWN_UNUSED
            self.notes.append(f"{self.where}: topics not used: {shown}" + (f" and {more} more" if more > 0 else ""))

    # Clocks

    def _frame_span_s(self) -> tuple[float, float]:
        return float(self.frame_ns[0]) * 1e-9, float(self.frame_ns[-1]) * 1e-9

    def _imu_span_s(self, offset_s: float) -> tuple[float, float]:
        return float(self.imu.t_s[0]) + offset_s, float(self.imu.t_s[-1]) + offset_s

    def _clock_fix_s(self) -> float:
        """0, or the IMU's offset to the camera clock from receive times when the stamps do not overlap."""
        if self.imu is None or not self.n_frames or spans_overlap(self._imu_span_s(0.0), self._frame_span_s()):
            return 0.0
        image_lag = np.median(self.frame_ns - self._image_receive_ns[self._kept])
        imu_ns, imu_receive_ns = self._imu_raw_ns
        offset_s = float(image_lag - np.median(imu_ns - imu_receive_ns)) * 1e-9
        if not spans_overlap(self._imu_span_s(offset_s), self._frame_span_s()):
            return 0.0  # refused when the stream starts (`_check_clocks`), after any --imu-time-offset-s
        self.fixes.append(f"{self.where}: the header stamps of {self.topics.image} and {self.topics.imu} do not "
                          f"overlap (another clock), and their receive times do: the IMU is put on the camera clock "
                          f"with imu_time_offset_s = {offset_s:.6f} s (from the median header-minus-receive times; "
                          "--imu-time-offset-s sets it yourself)")
        return offset_s

    def _check_clocks(self) -> None:
        offset_s = self.info.imu_time_offset_s
        if self.imu is None or not self.n_frames or spans_overlap(self._imu_span_s(offset_s), self._frame_span_s()):
            return
        (a, b), (c, d) = self._frame_span_s(), self._imu_span_s(offset_s)
        raise InputError(f"{self.where}: the header stamps of {self.topics.image} span {a:.6f} to {b:.6f} s and those "
                         f"of {self.topics.imu} {c:.6f} to {d:.6f} s (IMU offset {offset_s:g} s), with no overlap, and "
                         "the receive times do not line them up: the camera and the IMU are on different clocks "
                         "(give --imu-time-offset-s)")

    # Frames

    def _where_message(self, topic: str | None, k: int | None = None) -> str:
        return f"{self.where} {topic}" + ("" if k is None else f" message {k}")

    def _frame(self, i: int, image_raw, image_conn, depth_raw=None, depth_conn=None) -> Frame:
        """Frame `i` (yielded order) from its raw image message and, when paired, its depth message."""
        k = int(self._kept[i])
        try:
            rgb = ros.image_rgb(self._deserialize(image_raw, image_conn), self._where_message(self.topics.image, k))
            depth = None
            if depth_raw is not None:
                depth = ros.depth_metres(self._deserialize(depth_raw, depth_conn),
                                         self._where_message(self.topics.depth))
        except InputError as exc:  # met mid-stream: the source fails there
            raise SourceError(str(exc)) from None
        if depth is not None and depth.shape != rgb.shape[:2]:
            raise SourceError(f"{self.where}: {self.topics.depth} holds {depth.shape[1]}x{depth.shape[0]} depth and "
                              f"{self.topics.image} {rgb.shape[1]}x{rgb.shape[0]} images: depth must be registered "
                              "to the image (or pass --depth-topic of a registered one)")
        frame = Frame(t_s=float(self.frame_ns[i]) * 1e-9, rgb=rgb, depth=depth,
                      K=None if self.camera is None else self.camera.K, index=i)
        if self.camera is not None and self.camera.distorted:
            if self._undistorter is None:
                self._undistorter = Undistorter(self.camera, rgb.shape[:2])
            frame = self._undistorter.frame(frame)
        return frame

    def _frames(self) -> Iterator[Frame]:
        """Frames in order, each with its depth: images and depth come merged by receive time, and an
        image waits (with the ones after it) until its depth has come."""
        image_conns, depth_conns = self._connections(self.topics.image), self._connections(self.topics.depth)
        depth_of = self._depth_of or {}
        wanted_depth = set(depth_of.values())
        frame_of = {int(k): i for i, k in enumerate(self._kept)}
        waiting: deque = deque()
        depths: dict[int, tuple] = {}
        n_image = n_depth = 0
        for connection, _, raw in self.reader.messages(connections=image_conns + depth_conns):
            if connection.topic == self.topics.image:
                if n_image in frame_of:
                    waiting.append((n_image, raw, connection))
                n_image += 1
            else:
                if n_depth in wanted_depth:
                    depths[n_depth] = (raw, connection)
                n_depth += 1
            while waiting and (waiting[0][0] not in depth_of or depth_of[waiting[0][0]] in depths):
                k, image_raw, image_conn = waiting.popleft()
                depth_raw, depth_conn = depths.pop(depth_of[k]) if k in depth_of else (None, None)
                yield self._frame(frame_of[k], image_raw, image_conn, depth_raw, depth_conn)
        for k, image_raw, image_conn in waiting:  # a paired depth message that never came
            yield self._frame(frame_of[k], image_raw, image_conn)

    def _message_at(self, connections, receive_ns: int):
        for connection, _, raw in self.reader.messages(connections=connections, start=receive_ns, stop=receive_ns + 1):
            return raw, connection
        raise SourceError(f"{self.where}: a message at receive time {receive_ns} ns could not be read again")

    def sample_frames(self, n: int, limit: int | None = None) -> list[Frame] | None:
        """`Source.sample_frames`: frames spread over the bag, each read by its receive time."""
        frames = []
        for i in spread_indices(self.n_frames, n, limit):
            k = int(self._kept[i])
            image = self._message_at(self._connections(self.topics.image), int(self._image_receive_ns[k]))
            depth = (None, None)
            if self._depth_of and k in self._depth_of:
                depth = self._message_at(self._connections(self.topics.depth),
                                         int(self._depth_receive_ns[self._depth_of[k]]))
            try:
                frames.append(self._frame(i, *image, *depth))
            except SourceError:
                continue
        return frames

    def events(self) -> Iterator[Frame | ImuBatch]:
        if not self.info.has_frames:
            yield from split_by_span(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2, IMU_ONLY_BATCH_S)
            return
        self._check_clocks()
        batches = None if self.imu is None else [ImuBatch(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2)]
        yield from interleave(self._frames(), batches, self.info.imu_time_offset_s)

    def ground_truth(self) -> GroundTruth | None:
        if self.topics.pose is None:
            poses = self.topics.candidates.get("pose", {})
            if len(poses) > 1:  # several and none chosen: asking for ground truth is the error
                counts = {topic: info.msgcount for topic, info in self.reader.topics.items()}
                choose("pose", poses, None, self.where, counts, {})
            return None
        t_ns, quat_xyzw = self._poses
        if not len(t_ns):
            raise InputError(f"{self.where}: {self.topics.pose} holds no poses to evaluate against")
        order = np.argsort(t_ns, kind="stable")
        R_wb = Rotation.from_quat(quat_xyzw[order]).as_matrix()
        z_up = str(self._pose_frame_id).strip("/").lower() in Z_UP_FRAMES
        return GroundTruth(t_ns[order] * 1e-9, R_wb @ self.info.R_ci.T, gravity_aligned=z_up)

    def close(self) -> None:
        reader, self.reader = getattr(self, "reader", None), None
        if reader is not None and reader.stack is not None:
            reader.close()
