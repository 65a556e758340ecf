"""Foxglove's message types in JSON encoding: their JSON schemas (what the `mcap` channels declare)
and the message dictionaries, for the MCAP files `sinks.mcap_file` writes.

    schema = SCHEMAS["foxglove.FrameTransform"]        # bytes of a JSON schema
    message = frame_transform(t_ns, "world", "camera", quat_xyzw)

Field names, enums and units follow Foxglove's schemas (https://docs.foxglove.dev/docs/sdk/schemas):
times are `{"sec", "nsec"}`, colours r g b a in [0, 1], image points in pixels with the origin at the
top-left corner of the top-left pixel (OpenCV's pixel centres are at integers: add 0.5), binary data
base64. Only the fields written here are declared.
"""

from __future__ import annotations

import base64
import json

import numpy as np

LINE_LIST = 4
"""foxglove.PointsAnnotationType: individual segments 0-1, 2-3, ..."""
LINE_STRIP = 3

_TIME = {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0},
                                          "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
_NUMBER = {"type": "number"}
_XY = {"type": "object", "properties": {"x": _NUMBER, "y": _NUMBER}}
_XYZ = {"type": "object", "properties": {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER}}
_XYZW = {"type": "object", "properties": {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER, "w": _NUMBER}}
_COLOUR = {"type": "object", "properties": {"r": _NUMBER, "g": _NUMBER, "b": _NUMBER, "a": _NUMBER}}
_NUMBERS = {"type": "array", "items": _NUMBER}
_KEY_VALUES = {"type": "array", "items": {"type": "object", "properties": {"key": {"type": "string"},
                                                                           "value": {"type": "string"}}}}


def _schema(title: str, properties: dict) -> dict:
    return {"title": title, "type": "object", "properties": properties}


SCHEMA_OBJECTS = {
    "foxglove.CompressedImage": _schema("foxglove.CompressedImage", {
        "timestamp": _TIME, "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"}, "format": {"type": "string"}}),
    "foxglove.CameraCalibration": _schema("foxglove.CameraCalibration", {
        "timestamp": _TIME, "frame_id": {"type": "string"}, "width": {"type": "integer"},
        "height": {"type": "integer"}, "distortion_model": {"type": "string"}, "D": _NUMBERS, "K": _NUMBERS,
        "R": _NUMBERS, "P": _NUMBERS}),
    "foxglove.FrameTransform": _schema("foxglove.FrameTransform", {
        "timestamp": _TIME, "parent_frame_id": {"type": "string"}, "child_frame_id": {"type": "string"},
        "translation": _XYZ, "rotation": _XYZW}),
    "foxglove.ImageAnnotations": _schema("foxglove.ImageAnnotations", {
        "circles": {"type": "array", "items": _schema("foxglove.CircleAnnotation", {
            "timestamp": _TIME, "position": _XY, "diameter": _NUMBER, "thickness": _NUMBER,
            "fill_color": _COLOUR, "outline_color": _COLOUR})},
        "points": {"type": "array", "items": _schema("foxglove.PointsAnnotation", {
            "timestamp": _TIME, "type": {"type": "integer"}, "points": {"type": "array", "items": _XY},
            "outline_color": _COLOUR, "outline_colors": {"type": "array", "items": _COLOUR},
            "fill_color": _COLOUR, "thickness": _NUMBER, "metadata": _KEY_VALUES})},
        "texts": {"type": "array", "items": _schema("foxglove.TextAnnotation", {
            "timestamp": _TIME, "position": _XY, "text": {"type": "string"}, "font_size": _NUMBER,
            "text_color": _COLOUR, "background_color": _COLOUR, "metadata": _KEY_VALUES})}}),
}
SCHEMAS = {name: json.dumps(schema, separators=(",", ":")).encode() for name, schema in SCHEMA_OBJECTS.items()}


def time(t_ns: int) -> dict:
    """A Foxglove time of integer nanoseconds (clamped at 0: Foxglove times are unsigned)."""
    t_ns = max(int(t_ns), 0)
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def colour(rgb: tuple[int, int, int], alpha: float = 1.0) -> dict:
    """An 8-bit RGB colour as Foxglove's r g b a in [0, 1]."""
    return {"r": rgb[0] / 255.0, "g": rgb[1] / 255.0, "b": rgb[2] / 255.0, "a": float(alpha)}


def point(xy_opencv) -> dict:
    """An OpenCV pixel position (centres at integers) in Foxglove's image coordinates."""
    return {"x": float(xy_opencv[0]) + 0.5, "y": float(xy_opencv[1]) + 0.5}


def compressed_image(t_ns: int, frame_id: str, data: bytes, fmt: str = "jpeg") -> dict:
    return {"timestamp": time(t_ns), "frame_id": frame_id, "data": base64.b64encode(data).decode("ascii"),
            "format": fmt}


def camera_calibration(t_ns: int, frame_id: str, K: np.ndarray, height: int, width: int) -> dict:
    """A pinhole calibration of the (undistorted) frames: D empty, R identity, P = [K | 0]."""
    K = np.asarray(K, float)
    return {"timestamp": time(t_ns), "frame_id": frame_id, "width": int(width), "height": int(height),
            "distortion_model": "plumb_bob", "D": [0.0] * 5, "K": K.ravel().tolist(), "R": np.eye(3).ravel().tolist(),
            "P": np.hstack([K, np.zeros((3, 1))]).ravel().tolist()}


def frame_transform(t_ns: int, parent: str, child: str, quat_xyzw) -> dict:
    """The child frame's attitude in the parent frame (maps child coordinates to the parent's), at the origin."""
    x, y, z, w = (float(v) for v in quat_xyzw)
    return {"timestamp": time(t_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": {"x": 0.0, "y": 0.0, "z": 0.0}, "rotation": {"x": x, "y": y, "z": z, "w": w}}


def lines(t_ns: int, segments, rgb: tuple[int, int, int], thickness_px: float) -> dict:
    """A LINE_LIST points annotation of segments ((x0, y0), (x1, y1)) in OpenCV pixels."""
    points = [point(p) for segment in segments for p in segment]
    return {"timestamp": time(t_ns), "type": LINE_LIST, "points": points, "outline_color": colour(rgb),
            "outline_colors": [], "fill_color": colour(rgb, 0.0), "thickness": float(thickness_px), "metadata": []}


def text(t_ns: int, xy_opencv, content: str, font_size_px: float) -> dict:
    return {"timestamp": time(t_ns), "position": point(xy_opencv), "text": content, "font_size": float(font_size_px),
            "text_color": colour((255, 255, 255)), "background_color": colour((0, 0, 0), 0.6), "metadata": []}


def encode(message: dict) -> bytes:
    return json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
