"""Reading normal maps that users bring: `.npy`, `.npz`, or a normal PNG.

Array files hold normals (H, W, 3) in the camera frame, or (H, W, 4) with kappa as the last channel
(the learned estimator's output contract); `.npz` files name them `normals` and optionally `kappa`.
A normal PNG uses the paper's colouring, X-Y-Z to R-G-B: `n = rgb / max * 2 - 1`, 8 or 16 bit
(an alpha channel is ignored).
Bad files raise `InputError` naming the file: missing, empty, truncated or corrupt files, an .npz
given as .npy (or the reverse), an array header larger than the file or than `MAX_ARRAY_BYTES`
(refused before allocating), wrong shapes or dtypes. NaN/Inf normals or kappa are loaded as they
are: the solver ignores and counts such pixels (`n_invalid`).
`frame="opencv"` (default) reads the vectors as x right, y down, z forward; `frame="opengl"` as
x right, y up, z backward (converted to OpenCV here).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..types import NormalMap
from .images import read_image

MAX_ARRAY_BYTES = 2 << 30
"""Largest normal-map array we load (2 GiB: a 16k x 16k float32 map with kappa)."""

NORMAL_FRAMES = ("opencv", "opengl")
_OPENGL_TO_OPENCV = np.array([1.0, -1.0, -1.0], dtype=np.float32)


def load_normal_map(path: str | Path, frame: str = "opencv") -> NormalMap:
    """Load a normal map file; kappa is 1 everywhere unless the file carries it."""
    path = Path(path)
    if frame not in NORMAL_FRAMES:
        raise InputError(f"Unknown normal frame '{frame}'; use one of {', '.join(NORMAL_FRAMES)}")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, expected a normal-map file (.npy, .npz or .png)")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        normals, kappa = _split_channels(path, _load_npy(path))
    elif suffix == ".npz":
        normals, kappa = _load_npz(path)
    elif suffix in (".png", ".tif", ".tiff"):
        normals, kappa = _load_image(path), None
    else:
        raise InputError(f"{path}: unsupported normal map format '{suffix}' (use .npy, .npz or .png)")
    normals = normals.astype(np.float32, copy=False)
    if frame == "opengl":
        normals = normals * _OPENGL_TO_OPENCV
    if kappa is None:
        kappa = np.ones(normals.shape[:2], np.float32)
    return NormalMap(normals=normals, kappa=kappa.astype(np.float32, copy=False))


def _check_npy_header(path: Path, fh, available_bytes: int) -> None:
    """Refuse an array whose header declares more data than the file holds (or than MAX_ARRAY_BYTES)
    before numpy allocates it; `fh` is positioned at the start of the .npy data."""
    try:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise InputError(f"{path}: not a readable .npy array ({exc})") from None
    if dtype.hasobject:
        raise InputError(f"{path}: the array holds Python objects (dtype {dtype}), expected floating-point normals")
    n_bytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if n_bytes > min(available_bytes, MAX_ARRAY_BYTES):
        why = f"the limit is {MAX_ARRAY_BYTES >> 20} MiB" if n_bytes > MAX_ARRAY_BYTES else "the file holds less"
        raise InputError(f"{path}: the array header declares shape {shape} ({n_bytes / 2**20:.0f} MiB of {dtype}) "
                         f"but {why}")


def _load_npy(path: Path) -> np.ndarray:
    if zipfile.is_zipfile(path):
        raise InputError(f"{path}: this is an .npz archive (zip), not an .npy array; rename it to .npz")
    with open(path, "rb") as fh:
        _check_npy_header(path, fh, path.stat().st_size)
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise InputError(f"{path}: not a readable .npy array ({exc})") from None


def _load_npz(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    if not zipfile.is_zipfile(path):
        hint = "; it is an .npy array: rename it to .npy" if _is_npy(path) else ""
        raise InputError(f"{path}: not a readable .npz archive (not a zip file){hint}")
    try:
        with zipfile.ZipFile(path) as archive:
            members = {info.filename: info for info in archive.infolist()}
            keys = [name[:-4] for name in members if name.endswith(".npy")]
            if "normals" not in keys:
                raise InputError(f"{path}: expected an array named 'normals' (and optionally 'kappa'), found {keys}")
            for name in ("normals", "kappa"):
                if name in keys:
                    with archive.open(f"{name}.npy") as fh:
                        _check_npy_header(path, fh, members[f"{name}.npy"].file_size)
        with np.load(path, allow_pickle=False) as data:
            normals = data["normals"]
            kappa = data["kappa"] if "kappa" in keys else None
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}: not a readable .npz archive ({exc})") from None
    normals, kappa_channel = _split_channels(path, normals)
    kappa = kappa_channel if kappa is None else kappa
    if kappa is not None and kappa.shape != normals.shape[:2]:
        raise InputError(f"{path}: kappa has shape {kappa.shape}, expected {normals.shape[:2]} to match normals")
    if kappa is not None and not (np.issubdtype(kappa.dtype, np.floating) or np.issubdtype(kappa.dtype, np.integer)):
        raise InputError(f"{path}: expected kappa as real numbers, got dtype {kappa.dtype}")
    return normals, kappa


def _is_npy(path: Path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(6) == b"\x93NUMPY"


def _split_channels(path: Path, array: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    if array.ndim != 3 or array.shape[-1] not in (3, 4) or 0 in array.shape:
        raise InputError(f"{path}: expected normals of shape (H, W, 3) or (H, W, 4), got {array.shape}")
    if not np.issubdtype(array.dtype, np.floating):
        raise InputError(f"{path}: expected floating-point normals, got dtype {array.dtype}")
    if array.shape[-1] == 4:
        return array[..., :3], array[..., 3]
    return array, None


def _load_image(path: Path) -> np.ndarray:
    image = read_image(path, cv2.IMREAD_UNCHANGED, what="a normal image (X-Y-Z as R-G-B)")
    if image.ndim != 3 or image.shape[2] < 3:
        raise InputError(f"{path}: a normal image needs 3 colour channels, got shape {image.shape}")
    if image.dtype == np.uint8:
        full_scale = 255.0
    elif image.dtype == np.uint16:
        full_scale = 65535.0
    else:
        raise InputError(f"{path}: expected an 8- or 16-bit normal image, got dtype {image.dtype}")
    rgb = image[..., 2::-1].astype(np.float32)  # OpenCV reads BGR(A)
    return rgb * (2.0 / full_scale) - 1.0


def normals_to_rgb(normals: np.ndarray) -> np.ndarray:
    """The paper's colouring of normals (H, W, 3) in [-1, 1] as an RGB uint8 image (X-Y-Z to R-G-B)."""
    rgb = (np.nan_to_num(normals, nan=0.0) + 1.0) * 127.5
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
