"""Reading image files that users bring, with one clear `InputError` for every way they can be bad.

`read_image(path, flags, what)` is `cv2.imread` plus the checks it leaves out, and the EXIF
orientation applied in every mode (OpenCV skips it for `IMREAD_UNCHANGED`), so a phone's portrait
photo comes out upright: a missing, empty or
non-image file, a truncated or corrupt one, and an image too large to decode. PNG and JPEG headers
are checked BEFORE decoding (`image_size`), so a file that claims 30000 x 30000 pixels is refused
without allocating gigabytes; other formats rely on OpenCV's own limit (`cv2.error`, also turned
into an `InputError`).
"""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError

MAX_IMAGE_PIXELS = 8192 * 8192
"""Largest image we decode (67 Mpixel: 400 MB as 16-bit RGB); far beyond any camera frame we use."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SOI = b"\xff\xd8"
# JPEG start-of-frame markers (they carry the size): C0-CF except DHT (C4), JPG (C8) and DAC (CC).
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_JPEG_HEADER_BYTES = 1 << 20


def image_format(head: bytes) -> str | None:
    """'png', 'jpeg' or None (another or no image format) from a file's first bytes."""
    if head.startswith(_PNG_SIGNATURE):
        return "png"
    if head.startswith(_JPEG_SOI):
        return "jpeg"
    return None


def image_size(path: str | Path) -> tuple[int, int] | None:
    """(width, height) in pixels read from a PNG or JPEG header without decoding the image.

    None for other formats, or when the header does not hold a size (a corrupt file: decoding it
    then fails with its own message).
    """
    with open(path, "rb") as fh:
        head = fh.read(_JPEG_HEADER_BYTES)
    kind = image_format(head)
    if kind == "png":
        # The IHDR chunk comes first: length (4), b"IHDR", width (4), height (4), big-endian.
        if len(head) >= 24 and head[12:16] == b"IHDR":
            return struct.unpack(">II", head[16:24])
        return None
    if kind == "jpeg":
        pos = 2
        while pos + 9 <= len(head):
            if head[pos] != 0xFF:
                return None
            marker = head[pos + 1]
            if marker == 0xFF:  # fill byte
                pos += 1
                continue
            if marker in _JPEG_SOF:
                height, width = struct.unpack(">HH", head[pos + 5 : pos + 9])
                return width, height
            (length,) = struct.unpack(">H", head[pos + 2 : pos + 4])
            pos += 2 + length
    return None


EXIF_ORIENTATION_TAG = 0x0112


_PNG_EXIF_TEXT_KEYWORDS = (b"Raw profile type exif", b"XML:com.adobe.xmp")
"""Keywords of the PNG text chunks (tEXt, zTXt, iTXt) in which Pillow also finds an orientation."""


def png_without_exif(path: str | Path) -> bool:
    """True when `path` is a PNG none of whose chunks can hold an orientation for Pillow (an eXIf chunk,
    or a text chunk named in `_PNG_EXIF_TEXT_KEYWORDS`), read from the chunk headers alone; False for
    another format, such a chunk, or a file that ends before its IEND chunk. Pillow decodes a whole PNG
    to look for EXIF after the pixels (3.8 ms of CPU per 640x480 depth map, as much as the decode itself)."""
    try:
        with open(path, "rb") as fh:
            if fh.read(8) != _PNG_SIGNATURE:
                return False
            while len(header := fh.read(8)) == 8:
                length, kind = struct.unpack(">I4s", header)
                if kind == b"IEND":
                    return True
                if kind == b"eXIf":
                    return False
                skip = length + 4  # the data and its CRC
                if kind in (b"tEXt", b"zTXt", b"iTXt"):
                    keyword = fh.read(min(length, 80)).split(b"\0", 1)[0]
                    if keyword in _PNG_EXIF_TEXT_KEYWORDS:
                        return False
                    skip -= min(length, 80)
                fh.seek(skip, 1)
    except OSError:
        pass
    return False


def exif_orientation(path: str | Path) -> int:
    """The EXIF orientation code (1-8; 1 = as stored) of an image file, 1 when it has none."""
    from PIL import Image, UnidentifiedImageError

    if png_without_exif(path):
        return 1
    try:
        with Image.open(path) as image:
            code = int(image.getexif().get(EXIF_ORIENTATION_TAG, 1))
    except (OSError, UnidentifiedImageError, ValueError, TypeError):
        return 1
    return code if 1 <= code <= 8 else 1


def apply_orientation(image: np.ndarray, code: int) -> np.ndarray:
    """`image` (H, W[, C]) turned as EXIF orientation `code` says, so that it displays upright:
    2 mirror, 3 rotate 180, 4 flip, 5 transpose, 6 rotate 90 clockwise, 7 transverse, 8 rotate 90
    counter-clockwise."""
    turned = {
        1: lambda a: a, 2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1],
        5: lambda a: a.swapaxes(0, 1), 6: lambda a: np.rot90(a, -1), 7: lambda a: np.rot90(a, 2).swapaxes(0, 1),
        8: lambda a: np.rot90(a, 1),
    }[code](image)
    return np.ascontiguousarray(turned)


_REDUCED_COLOR = ((2, cv2.IMREAD_REDUCED_COLOR_2), (4, cv2.IMREAD_REDUCED_COLOR_4), (8, cv2.IMREAD_REDUCED_COLOR_8))


def reduction_for(size: tuple[int, int] | None, max_pixels: int | None) -> tuple[int, int | None]:
    """(factor, OpenCV flag) of the smallest of 1/2, 1/4, 1/8 that brings `size` (w, h) to at most
    `max_pixels`; (1, None) when no reduction is needed or the size is unknown."""
    if size is None or max_pixels is None or size[0] * size[1] <= max_pixels:
        return 1, None
    fitting = (pair for pair in _REDUCED_COLOR if (size[0] // pair[0]) * (size[1] // pair[0]) <= max_pixels)
    return next(fitting, _REDUCED_COLOR[-1])


def read_image(path: str | Path, flags: int = cv2.IMREAD_UNCHANGED, what: str = "image",
               max_pixels: int | None = None) -> np.ndarray:
    """`cv2.imread(path, flags)` (BGR(A) channel order, the file's bit depth for IMREAD_UNCHANGED).

    With `max_pixels`, a PNG or JPEG larger than that is decoded at 1/2, 1/4 or 1/8 of its size
    (8-bit BGR, `cv2.IMREAD_REDUCED_COLOR_*`: JPEG scales while decoding), so a 48-megapixel photo
    never lives in memory at full size beyond the decoder's own buffer.

    Raises `InputError` naming the file and `what` it should be for a missing or empty file, a
    file that is not an image (its first bytes are quoted), a header larger than `MAX_IMAGE_PIXELS`
    or with a zero side, and a truncated or corrupt image that OpenCV cannot decode.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder, expected {what}")
    if not path.is_file():
        raise InputError(f"{path}: no such file (expected {what})")
    n_bytes = path.stat().st_size
    if n_bytes == 0:
        raise InputError(f"{path}: empty file (0 bytes), expected {what}")
    size = image_size(path)
    if size is not None:
        width, height = size
        if width == 0 or height == 0:
            raise InputError(f"{path}: the image header declares {width} x {height} pixels (a zero side)")
        if width * height > MAX_IMAGE_PIXELS:
            raise InputError(
                f"{path}: the image header declares {width} x {height} pixels, more than the limit of "
                f"{MAX_IMAGE_PIXELS} pixels; refusing to decode it"
            )
    _, reduced = reduction_for(size, max_pixels)
    flags = flags if reduced is None else reduced
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # our message replaces OpenCV's log
    try:
        image = cv2.imread(str(path), flags)
    except cv2.error as exc:
        reason = str(exc).strip().splitlines()[-1]
        raise InputError(f"{path}: OpenCV cannot decode {what} ({reason})") from None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if image is None or image.size == 0:
        if not cv2.haveImageReader(str(path)):
            with open(path, "rb") as fh:
                head = fh.read(8)
            raise InputError(
                f"{path}: not a readable image, cannot decode it: not a format OpenCV reads (file starts with "
                f"{head!r}); expected {what}"
            )
        raise InputError(f"{path}: not a readable image, cannot decode it: corrupt or truncated ({n_bytes} bytes); "
                         f"expected {what}")
    if flags == cv2.IMREAD_UNCHANGED:  # the other modes apply the EXIF orientation in OpenCV itself
        image = apply_orientation(image, exif_orientation(path))
    return image
