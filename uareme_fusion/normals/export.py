"""Normal maps of an image, a folder of images or a video, written as images and arrays.

    written = export_normals(Path("corridor.mp4"), Path("out"), LearnedNormals(), progress=callback)

Per input frame, under `out_dir` (`<stem>` is the image's file stem, or `<video stem>_<index:06d>`;
images of one folder that share a stem, `a.png` and `a.jpg`, keep their suffix: `a_png`, `a_jpg`):
- `<stem>_normals.png`: normals coloured X-Y-Z to R-G-B as in the paper (`normals_to_rgb`,
  camera frame OpenCV: x right, y down, z forward);
- `<stem>_confidence.png`: kappa / kappa_cap as 8-bit grey (white = confident, black = kappa 0);
- `<stem>.npz`: `normals` (H, W, 3) float32 unit vectors and `kappa` (H, W) float32, the layout
  `io.normal_maps.load_normal_map` reads back (so these files can stand in for a network later).
Images are read with OpenCV; an unreadable or empty image raises `InputError` naming the file.
Every file is written atomically (`io.safe_files`): an interrupted export leaves complete files only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np

from ..errors import InputError
from ..formats.images import IMAGE_SUFFIXES, VIDEO_SUFFIXES, images_in_folder, read_rgb
from ..io.normal_maps import normals_to_rgb
from ..io.safe_files import write_image_atomic, write_npz_atomic
from ..types import NormalMap



def list_frames(input_path: Path) -> tuple[int, Iterator[tuple[str, np.ndarray]]]:
    """(frame count, iterator of (stem, RGB uint8 image)) for an image, a folder of images or a video."""
    path = Path(input_path)
    if path.is_dir():
        files = images_in_folder(path)
        if not files:
            raise InputError(f"{path}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
        return len(files), ((stem, read_rgb(p)) for stem, p in zip(unique_stems(files), files))
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    suffix = path.suffix.lower()
    if suffix in IMAGE_SUFFIXES:
        return 1, iter([(path.stem, read_rgb(path))])
    if suffix in VIDEO_SUFFIXES:
        return _video_frames(path)
    raise InputError(f"{path}: not an image ({', '.join(IMAGE_SUFFIXES)}), a video "
                     f"({', '.join(VIDEO_SUFFIXES)}) or a folder of images")


def unique_stems(files: list[Path]) -> list[str]:
    """File stems, with the suffix kept (`a_png`) for files whose stem another file shares."""
    stems = [p.stem for p in files]
    shared = {s for s in stems if stems.count(s) > 1}
    names = [f"{p.stem}_{p.suffix[1:].lower()}" if p.stem in shared else p.stem for p in files]
    clashes = sorted({n for n in names if names.count(n) > 1})
    if clashes:
        clashing = [str(p) for p, name in zip(files, names) if name in clashes]
        raise InputError(f"{', '.join(clashing)}: these images would write the same outputs ({', '.join(clashes)}); "
                         "rename them")
    return names


def _video_frames(path: Path) -> tuple[int, Iterator[tuple[str, np.ndarray]]]:
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file (0 bytes), expected a video")
    capture = cv2.VideoCapture(str(path))
    ok, first = capture.read() if capture.isOpened() else (False, None)
    if not ok or first is None:
        capture.release()
        raise InputError(f"{path}: OpenCV cannot read a frame from this video")
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))

    def frames():
        index, frame = 0, first
        try:
            while frame is not None:
                yield f"{path.stem}_{index:06d}", cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
                index += 1
                ok, frame = capture.read()
                frame = frame if ok else None
        finally:
            capture.release()

    return max(count, 1), frames()


def confidence_image(kappa: np.ndarray, kappa_cap: float) -> np.ndarray:
    """kappa (H, W) as uint8 grey: 255 at or above `kappa_cap`, 0 at kappa 0."""
    return np.clip(np.rint(kappa * (255.0 / kappa_cap)), 0, 255).astype(np.uint8)


def write_normal_map(out_dir: Path, stem: str, normal_map: NormalMap, kappa_cap: float) -> None:
    """Write `<stem>_normals.png`, `<stem>_confidence.png` and `<stem>.npz` (see the module docstring)."""
    for name, image in ((f"{stem}_normals.png", normals_to_rgb(normal_map.normals)[..., ::-1]),
                        (f"{stem}_confidence.png", confidence_image(normal_map.kappa, kappa_cap))):
        write_image_atomic(out_dir / name, image)
    write_npz_atomic(out_dir / f"{stem}.npz", normals=normal_map.normals.astype(np.float32),
                     kappa=normal_map.kappa.astype(np.float32))


def export_normals(input_path: Path, out_dir: Path, estimator, kappa_cap: float,
                   progress: Callable[[int, int], None] | None = None, camera=None) -> int:
    """Estimate and write the normals of every frame of `input_path` under `out_dir` (created).

    `estimator.estimate(rgb_uint8) -> NormalMap`; `progress(done, total)` after each frame; `camera`
    (`drivers.intrinsics.CameraModel`) undistorts each frame first. Returns the number of frames written."""
    from ..drivers.intrinsics import Undistorter, check_camera

    undistort: dict[tuple, Callable] = {}  # per image size: the maps are computed once, not per frame
    total, frames = list_frames(input_path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    done = 0
    for stem, rgb in frames:
        if camera is not None:
            size = rgb.shape[:2]
            if size not in undistort:
                check_camera(camera, camera.origin, size)
                undistort[size] = Undistorter(camera, size).image if camera.distorted else (lambda image: image)
            rgb = undistort[size](rgb)
        write_normal_map(out, stem, estimator.estimate(rgb, source=stem), kappa_cap)
        done += 1
        if progress is not None:
            progress(done, max(total, done))
    return done
