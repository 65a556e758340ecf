"""Writing any `Source` into a ROS bag with `rosbags`' writers: ROS 1 `.bag`, ROS 2 with sqlite3 or MCAP.

    write_bag(open_source("sim_out/"), "sim.bag", storage="ros1")
    write_bag(open_source("sim_out/"), "sim_ros2", storage="mcap", image_encoding="jpeg")

What is written (`formats.ros_messages`; topics in `BagTopics`' defaults, `BAG_TOPICS`):
- each frame as a `sensor_msgs/Image` (`image_encoding` rgb8, bgr8 or mono8) or a
  `CompressedImage` (jpeg, png), its depth as `Image` 32FC1 (metres, exact) or 16UC1 (millimetres),
  and a `CameraInfo` with the frame's K (no distortion: frames are written as the source yields them);
- each IMU sample as `sensor_msgs/Imu`, stamped on the camera clock (IMU stamp + `imu_time_offset_s`);
- `/tf_static` (tf2_msgs/TFMessage) with the camera-IMU rotation `R_ci` (`camera_optical` <- `imu_link`)
  when the source has an IMU;
- the source's ground truth as `geometry_msgs/PoseStamped`, orientation `R_wc @ R_ci` (what
  `RosbagSource.ground_truth` reads back as `R_wc`), frame_id `world` when it is gravity-aligned,
  `mocap` otherwise.
Header stamps are the source's times plus `stamp_offset_s` (e.g. an epoch start); `image_stamp_shift_s`
moves the camera topics' header stamps only (a camera on another clock), `image_receive_delay_s`
makes the camera messages arrive late (receive time = stamp + delay). For tests and for converting a
dataset folder into a bag; frames are held one at a time.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.rotations import quat_xyzw
from uareme_fusion.types import Frame, ImuBatch

from ..formats import ros_messages as ros
from .base import Source

BAG_TOPICS = {"image": "/camera/image_raw", "camera_info": "/camera/camera_info", "depth": "/camera/depth/image_raw",
              "imu": "/imu/data", "pose": "/ground_truth/pose"}
CAMERA_FRAME_ID = "camera_optical"
IMU_FRAME_ID = "imu_link"
WORLD_FRAME_ID = "world"
"""The poses' frame_id when the source's ground truth is gravity-aligned (z up), else `MOCAP_FRAME_ID`."""
MOCAP_FRAME_ID = "mocap"
STORAGES = ("ros1", "sqlite3", "mcap")
IMAGE_ENCODINGS = ("rgb8", "bgr8", "mono8", "jpeg", "png")
DEPTH_ENCODINGS = ("32FC1", "16UC1")


def _writer(path: Path, storage: str):
    from rosbags.typesys import Stores, get_typestore

    if storage == "ros1":
        from rosbags.rosbag1 import Writer

        from rosbags.typesys import get_types_from_msg

        typestore = get_typestore(Stores.ROS1_NOETIC)
        typestore.register(get_types_from_msg(TF_MESSAGE_ROS1, "tf2_msgs/msg/TFMessage"))
        return Writer(path), typestore
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    return Writer(path, version=9, storage_plugin=plugin), get_typestore(Stores.ROS2_HUMBLE)


TF_MESSAGE_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"
"""tf2_msgs/TFMessage, which rosbags' ROS 1 type store does not carry."""


def _serialise(typestore, storage: str, msg) -> bytes:
    if storage == "ros1":
        return typestore.serialize_ros1(msg, msg.__msgtype__)
    return typestore.serialize_cdr(msg, msg.__msgtype__)


class _BagOut:
    def __init__(self, path: Path, storage: str):
        self.storage = storage
        self.bag, self.typestore = _writer(path, storage)
        self.types = self.typestore.types
        self.connections: dict[str, object] = {}
        self.counts: dict[str, int] = {}
        self.bag.open()

    def write(self, topic: str, msg, receive_ns: int) -> None:
        if topic not in self.connections:
            self.connections[topic] = self.bag.add_connection(topic, msg.__msgtype__, typestore=self.typestore)
        self.bag.write(self.connections[topic], int(receive_ns), _serialise(self.typestore, self.storage, msg))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def header(self, t_ns: int, frame_id: str):
        return ros.header(self.types, t_ns, frame_id, seq=sum(self.counts.values()))


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def _image(out: _BagOut, head, rgb: np.ndarray, encoding: str):
    if encoding == "rgb8":
        return ros.image_message(out.types, head, rgb, "rgb8")
    if encoding == "mono8":
        return ros.image_message(out.types, head, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), "mono8")
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    if encoding == "bgr8":
        return ros.image_message(out.types, head, bgr, "bgr8")
    return ros.compressed_message(out.types, head, bgr, encoding)


def _depth(out: _BagOut, head, depth_m: np.ndarray, encoding: str):
    depth = np.nan_to_num(np.asarray(depth_m, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if encoding == "32FC1":
        return ros.image_message(out.types, head, depth, "32FC1")
    mm = np.rint(depth * ros.MILLIMETRES_PER_METRE)
    return ros.image_message(out.types, head, np.where((mm > 0) & (mm < 65536), mm, 0).astype(np.uint16), "16UC1")


def write_bag(source: Source, path: str | Path, storage: str = "ros1", image_encoding: str = "rgb8",
              depth_encoding: str = "32FC1", stamp_offset_s: float = 0.0, image_stamp_shift_s: float = 0.0,
              image_receive_delay_s: float = 0.0, topics: dict[str, str] | None = None) -> dict[str, int]:
    """Write `source`'s frames, IMU and ground truth into a new bag at `path` (see the module
    docstring); returns the messages written per topic. `path` must not exist (a ROS 2 bag is a folder)."""
    if storage not in STORAGES or image_encoding not in IMAGE_ENCODINGS or depth_encoding not in DEPTH_ENCODINGS:
        raise InputError(f"write_bag: storage {storage!r}, image encoding {image_encoding!r}, depth encoding "
                         f"{depth_encoding!r}: expected one of {STORAGES}, {IMAGE_ENCODINGS}, {DEPTH_ENCODINGS}")
    topics = {**BAG_TOPICS, **(topics or {})}
    out = _BagOut(Path(path), storage)
    info = source.info
    imu_offset_s = stamp_offset_s + info.imu_time_offset_s
    camera_offset_s = stamp_offset_s + image_stamp_shift_s
    try:
        if info.has_imu:
            t_ns = _ns(stamp_offset_s)
            out.write("/tf_static", _static_transform(out, t_ns, info.R_ci), t_ns)
        for event in source.events():
            if isinstance(event, ImuBatch):
                for t_s, gyro, accel in zip(event.t_s, event.gyro_rad_s, event.accel_m_s2):
                    t_ns = _ns(t_s + imu_offset_s)
                    msg = ros.imu_message(out.types, out.header(t_ns, IMU_FRAME_ID), gyro, accel)
                    out.write(topics["imu"], msg, t_ns)
            elif isinstance(event, Frame):
                _write_frame(out, event, topics, _ns(event.t_s + camera_offset_s),
                             _ns(event.t_s + stamp_offset_s + image_receive_delay_s), image_encoding, depth_encoding)
        truth = source.ground_truth()
        if truth is not None:
            frame_id = WORLD_FRAME_ID if truth.gravity_aligned else MOCAP_FRAME_ID
            for t_s, R_wc in zip(truth.t_s, truth.R_wc):
                t_ns = _ns(t_s + stamp_offset_s)
                out.write(topics["pose"], ros.pose_message(out.types, out.header(t_ns, frame_id),
                                                           quat_xyzw(R_wc @ info.R_ci)), t_ns)
    finally:
        out.bag.close()
    return out.counts


def _static_transform(out: _BagOut, t_ns: int, R_ci: np.ndarray):
    """A TFMessage of the IMU frame's attitude in the camera frame (`R_ci`, no translation)."""
    types = out.types
    x, y, z, w = map(float, quat_xyzw(np.asarray(R_ci, float)))
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        rotation=types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w))
    stamped = types["geometry_msgs/msg/TransformStamped"](header=out.header(t_ns, CAMERA_FRAME_ID),
                                                          child_frame_id=IMU_FRAME_ID, transform=transform)
    return types["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def _write_frame(out: _BagOut, frame: Frame, topics: dict, t_ns: int, receive_ns: int, image_encoding: str,
                 depth_encoding: str) -> None:
    head = out.header(t_ns, CAMERA_FRAME_ID)
    if frame.rgb is not None:
        out.write(topics["image"], _image(out, head, frame.rgb, image_encoding), receive_ns)
        if frame.K is not None:
            height, width = frame.rgb.shape[:2]
            out.write(topics["camera_info"], ros.camera_info_message(out.types, head, frame.K, height, width),
                      receive_ns)
    if frame.depth is not None:
        out.write(topics["depth"], _depth(out, head, frame.depth, depth_encoding), receive_ns)
