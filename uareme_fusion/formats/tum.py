"""TUM RGB-D style sequences (TUM RGB-D, ICL-NUIM, and the simulator's output): readers and writers.

Layout: `rgb.txt` and `depth.txt` (`timestamp filename` lines), or `associations.txt`
(`t file t file`, rgb and depth in either order, as TUM's associate.py and ICL-NUIM write it);
`groundtruth.txt` (`timestamp tx ty tz qx qy qz qw`); optional `accelerometer.txt`
(`timestamp ax ay az`). Lines starting with `#` are comments. Depth PNGs are 16-bit with
`depth_scale` units per metre (5000 for TUM and ICL-NUIM; the simulator states its own in
scene.json and `load_tum_rgbd` reads it from there when present).

    seq = load_tum_rgbd("/path/to/sequence")
    for frame in seq.frames(): ...          # uareme_fusion.types.Frame (rgb uint8 RGB, depth m)
    t, p_w, quat_xyzw = seq.groundtruth      # TUM order: quaternion x y z w

Conventions: the ground-truth quaternion is whatever the file holds. For TUM and the simulator it
is the camera-to-world rotation `R_wc`; ICL-NUIM's published camera has its y axis flipped with
respect to OpenCV (fy < 0), which this reader does not change. Frames are paired by nearest
timestamp within `max_dt_s`; unpaired images are counted in `n_unpaired`, never silently lost.
Bad files raise `InputError` naming the file and the line: too few or ragged columns, a cell that is
not a number, NaN/Inf values, list and ground-truth times not strictly increasing, ground-truth
quaternions far from unit length; images through `uareme_fusion.io.images.read_image` and depth
through `read_depth_png` (16-bit, single channel, the rgb image's size).

Writers: `tum_trajectory_line` (one `t tx ty tz qx qy qz qw` row), `write_tum_table` (a whole table
with `#` header lines) and `tum_list_text` (a `timestamp filename` list).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from ..errors import InputError
from ..io.images import read_image
from ..io.safe_files import write_text_atomic
from ..io.text_tables import read_table
from ..types import Frame
from .depth_png import TUM_DEPTH_SCALE, read_depth_png

TUM_LIST_COLUMNS = ("timestamp [s]", "filename")
TUM_TRAJECTORY_COLUMNS = ("timestamp [s]", "tx [m]", "ty [m]", "tz [m]", "qx", "qy", "qz", "qw")
TUM_ACCELEROMETER_COLUMNS = ("timestamp [s]", "ax [m/s^2]", "ay [m/s^2]", "az [m/s^2]")
ASSOCIATION_COLUMNS = ("timestamp [s]", "filename", "timestamp [s]", "filename")
TUM_RGBD_GT_TIME_OFFSET_S = 0.027
"""Seconds added to a TUM RGB-D `groundtruth.txt`'s stamps to put them on the Kinect's clock (the
`--gt-time-offset-s` convention): the frame stamped t was seen at mocap time t - 0.027 s. The benchmark
stamps both streams with the recording computer's clock as they arrive (`rgb.txt`: "seconds since the
Unix epoch"), the Kinect's images after their exposure and USB transfer, the motion capture's poses
after its own pipeline; its tools (`associate.py`, `evaluate_ate.py`) take an `--offset` for such a
difference and leave it 0. Estimated here from the data, on the fr1 rpy TRAIN frames only
(`evaluation.time_offset.estimate_time_offset` on the depth-normal rotations of `eval --normals depth
--backend single --gt-time-offset-s 0`, `tools/estimate_gt_time_offset.py`): +26.8 ms, 95 % block-bootstrap
interval +14.6 .. +36.7 over 422 frames (first half +8.7, second half +37.3; +26.3 with the frames timed
at their depth images); mean ARE 4.86 -> 4.55 deg there. Applied by `drivers.tum.TumSource` to folders
named as TUM RGB-D sequences without scene.json or source.json, with a note; no other dataset is shifted."""
QUATERNION_NORM_TOLERANCE = 1e-2
"""Stored quaternions may deviate this much from unit length (rounding); more is a broken file."""


TUM_TRAJECTORY_HEADER = "timestamp tx ty tz qx qy qz qw"


TUM_ROW = "%.9f 0 0 0 %.9f %.9f %.9f %.9f\n"
"""One trajectory.tum row: time, position zeros, quaternion x y z w of `R_wc`."""


def tum_trajectory_line(t_s: float, quat_xyzw, p_w=None, fmt: str = ".9f") -> str:
    """One trajectory row `t tx ty tz qx qy qz qw` (newline-terminated); position `0 0 0` when p_w is None."""
    p = "0 0 0" if p_w is None else " ".join(format(float(v), fmt) for v in p_w)
    return f"{float(t_s):{fmt}} {p} " + " ".join(format(float(q), fmt) for q in quat_xyzw) + "\n"


def write_tum_table(path: Path, header: str, t_s: np.ndarray, columns: np.ndarray, fmt: str) -> None:
    """A TUM text table `t c1 c2 ...` with `# `-prefixed header lines, written atomically."""
    rows = np.column_stack([t_s, columns])
    text = io.StringIO()
    np.savetxt(text, rows, fmt=fmt, header=header, comments="# ")
    write_text_atomic(path, text.getvalue())


def tum_list_text(title: str, stamps: list[str], files: list[str]) -> str:
    """A `timestamp filename` image list with a `# title` line and the column line."""
    return f"# {title}\n# timestamp filename\n" + "".join(f"{s} {f}\n" for s, f in zip(stamps, files))


def read_tum_list(path: Path) -> tuple[np.ndarray, list[str]]:
    """`timestamp filename` lines -> (t_s (N,), filenames); times finite and strictly increasing."""
    table = read_table(path, TUM_LIST_COLUMNS, kind="a TUM image list")
    t = table.floats(0)
    table.require_finite(t, "timestamp")
    table.require_increasing(t)
    return t, table.strings(1)


def read_tum_trajectory(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`timestamp tx ty tz qx qy qz qw` -> (t_s (N,), p (N, 3) m, quat_xyzw (N, 4) unit).

    Times must be finite and strictly increasing, quaternions unit length within
    `QUATERNION_NORM_TOLERANCE` (they are renormalised); otherwise `InputError` naming the line."""
    table = read_table(path, TUM_TRAJECTORY_COLUMNS, kind="a TUM trajectory file")
    rows = table.floats(slice(0, 8))
    table.require_finite(rows, "value")
    table.require_increasing(rows[:, 0])
    norm = np.linalg.norm(rows[:, 4:8], axis=1)
    bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE
    if bad.any():
        raise InputError(f"{path}: {int(bad.sum())} quaternion(s) qx qy qz qw are not unit length "
                         f"({table.lines_where(bad)}; first norm {norm[bad][0]:.4g})")
    return rows[:, 0], rows[:, 1:4], rows[:, 4:8] / norm[:, None]


def read_tum_accelerometer(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """`timestamp ax ay az` -> (t_s (N,), accel_m_s2 (N, 3)); all values finite, rows in file order
    (as for EuRoC, the backends' IMU stream reorders and counts samples out of order)."""
    table = read_table(path, TUM_ACCELEROMETER_COLUMNS, kind="a TUM accelerometer file")
    rows = table.floats(slice(0, 4))
    table.require_finite(rows, "value")
    return rows[:, 0], rows[:, 1:4]


def read_associations(path: Path) -> tuple[np.ndarray, list[str], list[str]]:
    """`t file t file` lines (rgb and depth in either order) -> (t_rgb_s (N,), rgb files, depth files)."""
    table = read_table(path, ASSOCIATION_COLUMNS, kind="a TUM associations file")
    first = table.strings(1)[0] if len(table) else ""
    depth_first = "depth" in first and "rgb" not in first
    c_rgb, c_dep = (2, 0) if depth_first else (0, 2)
    t_rgb = table.floats(c_rgb)
    table.require_finite(t_rgb, "timestamp")
    table.require_increasing(t_rgb)
    return t_rgb, table.strings(c_rgb + 1), table.strings(c_dep + 1)


def associate(t_a: np.ndarray, t_b: np.ndarray, max_dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (ia, ib), ia ascending, pairing times of t_a with times of t_b (both sorted ascending)
    within max_dt_s, each used at most once, as TUM's `associate.py` pairs them: every pair within the
    tolerance, closest first (a greedy matching). Two rgb images nearest the same depth image thus both
    get one when a second depth image is within the tolerance of either (fr1 rpy train split: 488 of
    516 rgb images paired, 474 taking only each one's nearest)."""
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    if len(t_a) == 0 or len(t_b) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    lo, hi = np.searchsorted(t_b, t_a - max_dt_s, "left"), np.searchsorted(t_b, t_a + max_dt_s, "right")
    ia = np.repeat(np.arange(len(t_a)), hi - lo)
    ib = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi)]).astype(int) if len(ia) else np.zeros(0, int)
    keep = np.abs(t_b[ib] - t_a[ia]) <= max_dt_s
    ia, ib = ia[keep], ib[keep]
    used_a, used_b, pairs = set(), set(), []
    for k in np.lexsort((ia, np.abs(t_b[ib] - t_a[ia]))):  # closest first, ties in t_a's order
        if ia[k] not in used_a and ib[k] not in used_b:
            used_a.add(int(ia[k]))
            used_b.add(int(ib[k]))
            pairs.append((int(ia[k]), int(ib[k])))
    pairs.sort()
    return np.array([a for a, _ in pairs], int), np.array([b for _, b in pairs], int)


@dataclass(frozen=True)
class TumSequence:
    """An RGB-D sequence: paired image paths, optional ground truth and accelerometer."""

    root: Path
    t_s: np.ndarray
    """(N,) rgb timestamps of the paired frames, s."""
    rgb_paths: list[Path]
    depth_paths: list[Path | None]
    depth_scale: float
    groundtruth: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    """(t_s, p_w (M, 3) m, quat_xyzw (M, 4)) or None."""
    accelerometer: tuple[np.ndarray, np.ndarray] | None
    """(t_s, accel_m_s2 (M, 3)) or None."""
    K: np.ndarray | None
    n_unpaired: int = 0
    """rgb images without a depth image within max_dt_s (they are kept, with depth None)."""
    n_missing: int = 0
    """listed rgb images whose file does not exist (left out of the sequence)."""

    def __len__(self) -> int:
        return len(self.rgb_paths)

    def read_frame(self, i: int) -> Frame:
        """Frame i: rgb (H, W, 3) uint8 RGB order, depth (H, W) float32 m (0 = missing).

        `InputError` naming the file for an unreadable image, or depth that is not a 16-bit
        single-channel PNG of the rgb image's size. Grayscale, RGBA and 16-bit rgb images are
        converted to 8-bit RGB (OpenCV's IMREAD_COLOR)."""
        bgr = read_image(self.rgb_paths[i], cv2.IMREAD_COLOR, what=f"the rgb image of frame {i}")
        depth = None
        if self.depth_paths[i] is not None:
            raw = read_depth_png(self.depth_paths[i], 1.0, expected_shape=bgr.shape[:2])  # stored units
            depth = raw / np.float32(self.depth_scale)
        return Frame(float(self.t_s[i]), cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), depth, self.K, i)

    def frames(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self.read_frame(i)


def read_json_object(path: Path) -> dict:
    """A JSON file holding one object (scene.json, source.json); `InputError` naming the file otherwise."""
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable JSON file ({exc})") from None
    except RecursionError:
        raise InputError(f"{path}: not a readable JSON file (nested too deeply)") from None
    if not isinstance(meta, dict):
        raise InputError(f"{path}: expected a JSON object, got {type(meta).__name__}")
    return meta


def _read_scene_json(path: Path) -> dict:
    """The simulator's scene.json: `depth_scale` (> 0) and `K` (3, 3) are checked when present."""
    meta = read_json_object(path)
    out = {}
    if "depth_scale" in meta:
        scale = meta["depth_scale"]
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (np.isfinite(scale) and scale > 0):
            raise InputError(f"{path}: depth_scale must be a positive number, got {scale!r}")
        out["depth_scale"] = float(scale)
    if "K" in meta:
        try:
            K = np.asarray(meta["K"], dtype=float)
        except (TypeError, ValueError):
            K = None
        if K is None or K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise InputError(f"{path}: K must be a 3x3 matrix of numbers, got {meta['K']!r}")
        out["K"] = K
    return out


def load_tum_rgbd(root: str | Path, depth_scale: float | None = None, max_dt_s: float = 0.02) -> TumSequence:
    """Open a TUM RGB-D style folder (see the module docstring). `depth_scale` defaults to the
    simulator's scene.json value when present, else 5000 units per metre."""
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"TUM RGB-D folder {root} does not exist")
    if depth_scale is not None and not (np.isfinite(depth_scale) and depth_scale > 0):
        raise InputError(f"depth_scale must be a positive number of depth units per metre, got {depth_scale}")
    if not (np.isfinite(max_dt_s) and max_dt_s >= 0):
        raise InputError(f"max_dt_s must be a time >= 0 s, got {max_dt_s}")
    K = None
    scene_json = root / "scene.json"
    if scene_json.is_file():
        meta = _read_scene_json(scene_json)
        depth_scale = depth_scale or meta.get("depth_scale", TUM_DEPTH_SCALE)
        K = meta.get("K")
    depth_scale = depth_scale or TUM_DEPTH_SCALE

    n_unpaired = 0
    if (root / "rgb.txt").is_file():
        t_rgb, rgb_files = read_tum_list(root / "rgb.txt")
        t_dep, dep_files = read_tum_list(root / "depth.txt") if (root / "depth.txt").is_file() else (np.zeros(0), [])
        ia, ib = associate(t_rgb, t_dep, max_dt_s)
        depth_for = dict(zip(ia.tolist(), ib.tolist()))
        depth_paths = [root / dep_files[depth_for[i]] if i in depth_for else None for i in range(len(t_rgb))]
        n_unpaired = len(t_rgb) - len(ia) if len(dep_files) else 0
    elif (root / "associations.txt").is_file():
        t_rgb, rgb_files, dep_files = read_associations(root / "associations.txt")
        depth_paths = [root / f for f in dep_files]
    else:
        raise InputError(f"{root} has neither rgb.txt nor associations.txt (TUM RGB-D layout)")
    rgb_paths = [root / f for f in rgb_files]
    exists = np.array([p.is_file() for p in rgb_paths], bool)
    n_missing = int(np.sum(~exists))
    if not rgb_paths:
        raise InputError(f"{root}: the image list holds no frames")
    if n_missing == len(rgb_paths):
        raise InputError(f"{root}: none of the {len(rgb_paths)} listed rgb images exist")
    keep = np.flatnonzero(exists)
    t_rgb = np.asarray(t_rgb, float)[keep]
    rgb_paths = [rgb_paths[i] for i in keep]
    depth_paths = [depth_paths[i] for i in keep]
    gt = read_tum_trajectory(root / "groundtruth.txt") if (root / "groundtruth.txt").is_file() else None
    acc = read_tum_accelerometer(root / "accelerometer.txt") if (root / "accelerometer.txt").is_file() else None
    return TumSequence(root, t_rgb, rgb_paths, depth_paths, float(depth_scale), gt, acc, K, n_unpaired, n_missing)
