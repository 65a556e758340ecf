"""The camera-IMU rotation of a ROS bag from its static transforms (`/tf_static`, tf2_msgs/TFMessage).

    R_ci = static_rotation(reader, "camera_optical", "imu_link")   # (3, 3), or None when not connected

A TF transform with `header.frame_id` P and `child_frame_id` C gives C's pose in P, i.e. `R_PC`
(`v_P = R_PC v_C`). The static transforms form a graph of frames; the rotation between two frames is
the product along the path that joins them (breadth first; translations are not needed). Frame names
are compared without a leading `/` (ROS 1 names often have one).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy.spatial.transform import Rotation

from ..formats import ros_messages as ros

TF_STATIC_TOPIC = "/tf_static"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"


def _name(frame_id: str) -> str:
    return str(frame_id).strip().lstrip("/")


def static_edges(reader) -> dict[str, list[tuple[str, np.ndarray]]]:
    """frame -> [(neighbour, R_frame_neighbour)] from every `/tf_static` TFMessage of an open reader."""
    edges: dict[str, list[tuple[str, np.ndarray]]] = {}
    connections = [c for c in reader.connections if c.topic == TF_STATIC_TOPIC and c.msgtype == TF_MESSAGE]
    for connection, _, raw in reader.messages(connections=connections) if connections else ():
        for transform in reader.deserialize(raw, connection.msgtype).transforms:
            parent, child = _name(transform.header.frame_id), _name(transform.child_frame_id)
            R_pc = Rotation.from_quat(ros.quaternion_xyzw(transform.transform.rotation)).as_matrix()
            edges.setdefault(parent, []).append((child, R_pc))
            edges.setdefault(child, []).append((parent, R_pc.T))
    return edges


def static_rotation(reader, target_frame: str, source_frame: str) -> np.ndarray | None:
    """`R_target_source` (maps source-frame vectors to the target frame) through `/tf_static`; the
    identity for one frame named twice; None when no chain of static transforms joins them."""
    target, source = _name(target_frame), _name(source_frame)
    if target == source:
        return np.eye(3)
    edges = static_edges(reader)
    reached = {target: np.eye(3)}
    queue = deque([target])
    while queue:
        frame = queue.popleft()
        for neighbour, R_frame_neighbour in edges.get(frame, []):
            if neighbour not in reached:
                reached[neighbour] = reached[frame] @ R_frame_neighbour
                if neighbour == source:
                    return reached[neighbour]
                queue.append(neighbour)
    return None
