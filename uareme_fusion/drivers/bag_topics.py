"""Which topics of a ROS bag feed which input: found by message type, chosen by the user when ambiguous.

    topics = choose_topics(reader, "drive.bag", image_topic=None, imu_topic="/imu/data")
    topics.image, topics.depth, topics.camera_info, topics.imu, topics.pose   # topic names or None

Roles and the message types that fill them:
- image: `sensor_msgs/Image` in a colour or mono encoding, or `sensor_msgs/CompressedImage`;
- depth: `sensor_msgs/Image` in 16UC1 or 32FC1, or a compressedDepth `CompressedImage` (told from the
  image role by its first message's encoding);
- camera_info: `sensor_msgs/CameraInfo`; with several, the one in the image topic's namespace
  (`/cam/camera_info` for `/cam/image_raw` or `/cam/image_raw/compressed`), as image_transport pairs them;
- imu: `sensor_msgs/Imu`;
- pose (ground truth): `geometry_msgs/PoseStamped`, `geometry_msgs/PoseWithCovarianceStamped` or
  `nav_msgs/Odometry`; with several and none chosen, asking for ground truth is the error, not opening.
A role with one candidate takes it; with none it stays empty; with several the option (`--image-topic`,
`--depth-topic`, `--camera-info-topic`, `--imu-topic`, `--gt-topic`) chooses, and the `InputError`
(one line, naming the bag) lists the candidates. A chosen topic that is absent or of another type is
refused the same way.
"""

from __future__ import annotations

import posixpath
from dataclasses import dataclass, field

from ..errors import InputError
from ..formats import ros_messages as ros

POSE_TYPES = (ros.POSE_STAMPED, "geometry_msgs/msg/PoseWithCovarianceStamped", ros.ODOMETRY)
ROLE_OPTIONS = {"image": "--image-topic", "depth": "--depth-topic", "camera_info": "--camera-info-topic",
                "imu": "--imu-topic", "pose": "--gt-topic"}
ROLE_WORDS = {"image": "image", "depth": "depth", "camera_info": "CameraInfo", "imu": "IMU",
              "pose": "pose (ground truth)"}
SHOWN_CANDIDATES = 6


@dataclass(frozen=True)
class BagTopics:
    """The topic chosen for each role (None: the bag has none), the candidates of each role
    (topic -> message type), and the bag's other topics (unused)."""

    image: str | None = None
    depth: str | None = None
    camera_info: str | None = None
    imu: str | None = None
    pose: str | None = None
    candidates: dict[str, dict[str, str]] = field(default_factory=dict)
    unused: dict[str, str] = field(default_factory=dict)


def _first_message(reader, connections):
    for connection, _, raw in reader.messages(connections=connections):
        return reader.deserialize(raw, connection.msgtype)
    return None


def topic_roles(reader) -> tuple[dict[str, dict[str, str]], dict[str, str]]:
    """(role -> {topic: message type}, {unused topic: message type}) of an open `AnyReader`."""
    roles: dict[str, dict[str, str]] = {role: {} for role in ROLE_OPTIONS}
    unused: dict[str, str] = {}
    for topic, info in sorted(reader.topics.items()):
        msgtype = info.msgtype or "?"
        if msgtype in (ros.IMAGE, ros.COMPRESSED_IMAGE):
            first = _first_message(reader, info.connections) if info.msgcount else None
            role = "depth" if first is not None and ros.is_depth_message(first) else "image"
        elif msgtype == ros.CAMERA_INFO:
            role = "camera_info"
        elif msgtype == ros.IMU:
            role = "imu"
        elif msgtype in POSE_TYPES:
            role = "pose"
        else:
            unused[topic] = msgtype
            continue
        roles[role][topic] = msgtype
    return roles, unused


def _listing(candidates: dict[str, str], counts: dict[str, int]) -> str:
    shown = [f"{t} ({m.replace('/msg/', '/')}, {counts.get(t, 0)} messages)"
             for t, m in list(candidates.items())[:SHOWN_CANDIDATES]]
    more = len(candidates) - SHOWN_CANDIDATES
    return ", ".join(shown) + (f" and {more} more" if more > 0 else "")


def _same_namespace(candidates: dict[str, str], image_topic: str | None) -> str | None:
    """The one candidate whose namespace holds `image_topic` most closely, as image_transport pairs
    `<ns>/camera_info` with `<ns>/image_raw[/compressed]`."""
    if image_topic is None:
        return None
    scored = {}
    for topic in candidates:
        namespace = posixpath.dirname(topic).rstrip("/") + "/"
        if image_topic.startswith(namespace):
            scored[topic] = len(namespace)
    if not scored:
        return None
    best = max(scored.values())
    closest = [t for t, score in scored.items() if score == best]
    return closest[0] if len(closest) == 1 else None


def choose(role: str, candidates: dict[str, str], given: str | None, where: str, counts: dict[str, int],
           all_topics: dict[str, str], image_topic: str | None = None, required: bool = True) -> str | None:
    """The topic for `role` (see the module docstring); `InputError` naming `where` when it is
    ambiguous (unless not `required`: then None) or `given` is not such a topic."""
    option, word = ROLE_OPTIONS[role], ROLE_WORDS[role]
    if given is not None:
        if given in candidates:
            return given
        if given not in all_topics:
            known = f"its {word} topics: {_listing(candidates, counts)}" if candidates else f"it has no {word} topic"
            raise InputError(f"{where}: {option} {given}: no such topic in the bag; {known}")
        raise InputError(f"{where}: {option} {given}: is a {all_topics[given].replace('/msg/', '/')} topic, not "
                         f"{word} (" + (f"{word} topics: {_listing(candidates, counts)})" if candidates
                                        else f"the bag has no {word} topic)"))
    if len(candidates) <= 1:
        return next(iter(candidates), None)
    if role == "camera_info":
        paired = _same_namespace(candidates, image_topic)
        if paired is not None:
            return paired
    if not required:
        return None
    raise InputError(f"{where}: {len(candidates)} {word} topics: {_listing(candidates, counts)}; choose one with "
                     f"{option}")


def choose_topics(reader, where: str, **given: str | None) -> BagTopics:
    """`BagTopics` of an open `AnyReader`; `given` holds `image_topic`, `depth_topic`,
    `camera_info_topic`, `imu_topic`, `gt_topic` (None: found by type)."""
    roles, unused = topic_roles(reader)
    counts = {topic: info.msgcount for topic, info in reader.topics.items()}
    all_topics = {topic: info.msgtype or "?" for topic, info in reader.topics.items()}
    option_of = {"image": "image_topic", "depth": "depth_topic", "camera_info": "camera_info_topic",
                 "imu": "imu_topic", "pose": "gt_topic"}
    chosen: dict[str, str | None] = {}
    for role in ("image", "depth", "camera_info", "imu", "pose"):
        chosen[role] = choose(role, roles[role], given.get(option_of[role]), where, counts, all_topics,
                              image_topic=chosen.get("image"), required=role != "pose")
    return BagTopics(**chosen, candidates=roles, unused=unused)
