"""ROS messages as arrays and back (ROS 1 and ROS 2 alike, as `rosbags` deserialises them).

    rgb = image_rgb(msg, where)              # sensor_msgs/Image or CompressedImage -> (H, W, 3) uint8 RGB
    depth_m = depth_metres(msg, where)       # 16UC1 (mm), 32FC1 (m) or compressedDepth -> (H, W) float32 m
    K, dist, model, size = camera_info_fields(msg, where)    # sensor_msgs/CameraInfo, as given
    t_ns = stamp_ns(msg.header)

Encodings (REP 118 and `sensor_msgs/image_encodings.h`): images `rgb8`, `bgr8`, `rgba8`, `bgra8`,
`mono8`, `mono16` (and `8UC1`, `8UC3` read as mono8 and bgr8); depth `16UC1` (millimetres, 0 = none)
and `32FC1` (metres, NaN or 0 = none); `CompressedImage` as OpenCV decodes it (jpeg, png), and
`compressedDepth` (a 12-byte header, then a 16-bit PNG in millimetres). Rows may be padded (`step`);
big-endian data is swapped. Anything else is an `InputError` naming `where` and the encoding.

Field names differ between the ROS versions' CameraInfo (`K`, `D` in ROS 1; `k`, `d` in ROS 2): both
are read. The writers (`image_message`, ...) build messages from a `rosbags` typestore for
`drivers.rosbag_writer`.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError
from .images import to_rgb8

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMU = "sensor_msgs/msg/Imu"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ODOMETRY = "nav_msgs/msg/Odometry"

COLOUR_ENCODINGS = {"rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3), "rgba8": (np.uint8, 4), "bgra8": (np.uint8, 4),
                    "mono8": (np.uint8, 1), "mono16": (np.uint16, 1), "8uc1": (np.uint8, 1), "8uc3": (np.uint8, 3)}
DEPTH_ENCODINGS = {"16uc1": (np.uint16, 1), "32fc1": (np.float32, 1)}
MILLIMETRES_PER_METRE = 1000.0
COMPRESSED_DEPTH_HEADER_BYTES = 12
"""`compressed_depth_image_transport` puts a 12-byte config (format and quantisation) before the PNG."""


def stamp_ns(header) -> int:
    """A header's stamp as integer nanoseconds (ROS 1 and ROS 2 `Time` both read as sec, nanosec)."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def raw_stamp_ns(raw: bytes, cdr: bool) -> int:
    """The header stamp of a serialised message that starts with a std_msgs/Header (Image,
    CompressedImage, ...), read without deserialising it: bytes 4-12 hold sec and nanosec in both
    ROS 1 (after the uint32 seq, little-endian) and CDR (after the 4-byte encapsulation header, whose
    second byte says little- (1) or big-endian (0))."""
    order = "<" if not cdr or raw[1] == 1 else ">"
    sec, nanosec = np.frombuffer(bytes(raw[4:12]), f"{order}u4")
    return int(sec) * 1_000_000_000 + int(nanosec)


def encoding_of(msg) -> str:
    """The lower-case encoding of an Image, or the format string of a CompressedImage."""
    return str(getattr(msg, "encoding", None) or getattr(msg, "format", "")).strip().lower()


def is_depth_message(msg) -> bool:
    """True for a depth map (16UC1, 32FC1, compressedDepth), False for an image to look at."""
    encoding = encoding_of(msg)
    return encoding in DEPTH_ENCODINGS or "compresseddepth" in encoding


def _raw_array(msg, where: str, table: dict) -> np.ndarray:
    encoding = encoding_of(msg)
    if encoding not in table:
        raise InputError(f"{where}: image encoding {msg.encoding!r} is not supported (expected one of "
                         f"{', '.join(sorted(table))})")
    dtype, channels = table[encoding]
    dtype = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    row_bytes = width * channels * dtype.itemsize
    data = np.asarray(msg.data, np.uint8)
    if height <= 0 or width <= 0 or step < row_bytes or data.size < step * (height - 1) + row_bytes:
        raise InputError(f"{where}: a {width}x{height} {msg.encoding} image needs {row_bytes} bytes a row and "
                         f"step {step} gives {data.size} bytes in all: the message is inconsistent")
    rows = np.lib.stride_tricks.as_strided(data, (height, row_bytes), (step, 1))
    array = np.ascontiguousarray(rows).view(dtype).reshape(height, width, channels)
    return array.astype(dtype.newbyteorder("="), copy=False)


def _decode(msg, where: str, flags: int) -> np.ndarray:
    data = np.asarray(msg.data, np.uint8)
    image = cv2.imdecode(data, flags) if data.size else None
    if image is None:
        raise InputError(f"{where}: a CompressedImage of format {msg.format!r} ({data.size} bytes) does not decode")
    return image


def image_rgb(msg, where: str) -> np.ndarray:
    """An Image or CompressedImage message as (H, W, 3) uint8 RGB (16-bit scaled as image files are)."""
    if hasattr(msg, "format"):
        return to_rgb8(_decode(msg, where, cv2.IMREAD_UNCHANGED))
    array = _raw_array(msg, where, COLOUR_ENCODINGS)
    encoding = encoding_of(msg)
    if encoding in ("rgb8", "rgba8"):
        return np.ascontiguousarray(array[..., :3])
    return to_rgb8(array[..., 0] if array.shape[2] == 1 else array)  # bgr(a)8 and mono as OpenCV reads them


def depth_metres(msg, where: str) -> np.ndarray:
    """A depth message as (H, W) float32 metres, 0 where there is none (16UC1 and compressedDepth are
    millimetres, 32FC1 metres)."""
    if hasattr(msg, "format"):
        if "compresseddepth" not in encoding_of(msg) or "16uc1" not in encoding_of(msg):
            raise InputError(f"{where}: depth as CompressedImage must be 16UC1 compressedDepth, got format "
                             f"{msg.format!r}")
        data = np.asarray(msg.data, np.uint8)[COMPRESSED_DEPTH_HEADER_BYTES:]
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if image is None or image.dtype != np.uint16:
            raise InputError(f"{where}: a compressedDepth message does not hold a 16-bit PNG")
        return image.astype(np.float32) / MILLIMETRES_PER_METRE
    array = _raw_array(msg, where, DEPTH_ENCODINGS)[..., 0]
    if array.dtype == np.uint16:
        return array.astype(np.float32) / MILLIMETRES_PER_METRE
    depth = array.astype(np.float32)
    depth[~np.isfinite(depth)] = 0.0
    return depth


def _field(msg, *names):
    for name in names:
        if hasattr(msg, name):
            return np.asarray(getattr(msg, name), float)
    raise AttributeError(names[0])


def camera_info_fields(msg, where: str) -> tuple[np.ndarray, np.ndarray, str, tuple[int, int] | None]:
    """A CameraInfo message's (K (3, 3), D as given (empty when all zero), model: `plumb_bob` and
    `rational_polynomial` as radtan, `equidistant` as fisheye; (height, width) it was made for)."""
    K = _field(msg, "k", "K").reshape(3, 3)
    dist = _field(msg, "d", "D").ravel()
    model = str(msg.distortion_model).strip().lower() or "plumb_bob"
    names = {"plumb_bob": "radtan", "rational_polynomial": "radtan", "equidistant": "equidistant"}
    if model not in names:
        raise InputError(f"{where}: distortion model {msg.distortion_model!r} is not supported "
                         f"({', '.join(names)})")
    if K[0, 0] == 0 and K[1, 1] == 0:
        raise InputError(f"{where}: CameraInfo K is all zeros (the camera is not calibrated)")
    size = (int(msg.height), int(msg.width)) if msg.height and msg.width else None
    return K, dist if np.any(dist) else np.zeros(0), names[model], size


def vector3(value) -> np.ndarray:
    return np.array([value.x, value.y, value.z], float)


def quaternion_xyzw(value) -> np.ndarray:
    return np.array([value.x, value.y, value.z, value.w], float)


# Writing (rosbag_writer): messages built from a rosbags typestore's classes.

def header(types, t_ns: int, frame_id: str, seq: int = 0):
    """A std_msgs/Header for ROS 1 (with `seq`) or ROS 2, from a typestore's `types`."""
    Time, Header = types["builtin_interfaces/msg/Time"], types["std_msgs/msg/Header"]
    stamp = Time(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000))
    ros1 = "seq" in Header.__dataclass_fields__
    return Header(seq=seq, stamp=stamp, frame_id=frame_id) if ros1 else Header(stamp=stamp, frame_id=frame_id)


def image_message(types, head, array: np.ndarray, encoding: str):
    """A sensor_msgs/Image of `array` ((H, W) or (H, W, C), its bytes as they are) with `encoding`."""
    array = np.ascontiguousarray(array)
    height, width = array.shape[:2]
    return types[IMAGE](header=head, height=height, width=width, encoding=encoding, is_bigendian=0,
                        step=int(array.strides[0]), data=array.view(np.uint8).ravel())


def compressed_message(types, head, bgr: np.ndarray, fmt: str):
    """A sensor_msgs/CompressedImage of an OpenCV image encoded as `fmt` (jpeg or png)."""
    ok, data = cv2.imencode(f".{'jpg' if fmt == 'jpeg' else fmt}", bgr)
    if not ok:
        raise InputError(f"OpenCV cannot encode an image as {fmt}")
    return types[COMPRESSED_IMAGE](header=head, format=fmt, data=data.ravel())


def camera_info_message(types, head, K: np.ndarray, height: int, width: int):
    """A sensor_msgs/CameraInfo with `K`, no distortion (plumb_bob, D zeros), P = [K | 0]."""
    Info = types[CAMERA_INFO]
    lower = "k" in Info.__dataclass_fields__
    P = np.hstack([np.asarray(K, float), np.zeros((3, 1))]).ravel()
    arrays = {"d": np.zeros(5), "k": np.asarray(K, float).ravel(), "r": np.eye(3).ravel(), "p": P}
    arrays = arrays if lower else {name.upper(): value for name, value in arrays.items()}
    roi = types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return Info(header=head, height=height, width=width, distortion_model="plumb_bob", binning_x=0, binning_y=0,
                roi=roi, **arrays)


def imu_message(types, head, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray):
    """A sensor_msgs/Imu with rates and specific force; orientation unknown (covariance[0] = -1)."""
    Vector3, Quaternion = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    unknown = np.zeros(9)
    unknown[0] = -1.0
    return types[IMU](header=head, orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=unknown,
                      angular_velocity=Vector3(*map(float, gyro_rad_s)), angular_velocity_covariance=np.zeros(9),
                      linear_acceleration=Vector3(*map(float, accel_m_s2)), linear_acceleration_covariance=np.zeros(9))


def pose_message(types, head, quat_xyzw: np.ndarray):
    """A geometry_msgs/PoseStamped with orientation `quat_xyzw` at the origin."""
    Pose, Point, Quaternion = (types[f"geometry_msgs/msg/{n}"] for n in ("Pose", "Point", "Quaternion"))
    x, y, z, w = map(float, quat_xyzw)
    return types[POSE_STAMPED](header=head, pose=Pose(position=Point(x=0.0, y=0.0, z=0.0),
                                                      orientation=Quaternion(x=x, y=y, z=z, w=w)))
