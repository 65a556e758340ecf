"""The EXIF orientation of PNGs read from their chunk headers: Pillow's answer, without decoding the
pixels, for PNGs without EXIF (a camera's frames and depth maps); PNGs that hold an orientation (an eXIf
chunk before or after the pixels, an XMP or ImageMagick raw-profile text chunk) still go to Pillow."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image, PngImagePlugin

from uareme_fusion.io.images import exif_orientation, png_without_exif, read_image


def pillow_orientation(path) -> int:
    with Image.open(path) as image:
        return int(image.getexif().get(0x0112, 1))


def chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def with_chunk_after_pixels(png: bytes, kind: bytes, data: bytes) -> bytes:
    """`png` with one more chunk between its last IDAT and IEND (where Pillow finds it only by decoding)."""
    end = png.rindex(b"IEND") - 4
    return png[:end] + chunk(kind, data) + png[end:]


def exif_bytes(code: int) -> bytes:
    exif = Image.Exif()
    exif[0x0112] = code
    return exif.tobytes()


@pytest.fixture
def pngs(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (24, 40, 3), np.uint8)
    paths = {}
    cv2.imwrite(str(tmp_path / "opencv.png"), rgb)
    cv2.imwrite(str(tmp_path / "depth.png"), np.arange(24 * 40, dtype=np.uint16).reshape(24, 40))
    paths["opencv"], paths["depth"] = tmp_path / "opencv.png", tmp_path / "depth.png"
    text = PngImagePlugin.PngInfo()
    text.add_text("Comment", "no orientation here")
    Image.fromarray(rgb).save(tmp_path / "text.png", pnginfo=text)
    paths["text"] = tmp_path / "text.png"
    Image.fromarray(rgb).save(tmp_path / "exif_first.png", exif=exif_bytes(6))
    paths["exif_first"] = tmp_path / "exif_first.png"
    plain = (tmp_path / "opencv.png").read_bytes()
    (tmp_path / "exif_last.png").write_bytes(with_chunk_after_pixels(plain, b"eXIf", exif_bytes(8)))
    paths["exif_last"] = tmp_path / "exif_last.png"
    xmp = b'XML:com.adobe.xmp\0\0\0\0\0<x:xmpmeta><rdf:Description tiff:Orientation="3"/></x:xmpmeta>'
    (tmp_path / "xmp.png").write_bytes(with_chunk_after_pixels(plain, b"iTXt", xmp))
    paths["xmp"] = tmp_path / "xmp.png"
    (tmp_path / "truncated.png").write_bytes(plain[: len(plain) // 2])
    paths["truncated"] = tmp_path / "truncated.png"
    return paths


def test_pngs_without_exif_are_told_from_their_chunks_as_pillow_tells_them(pngs):
    expected = {"opencv": 1, "depth": 1, "text": 1, "exif_first": 6, "exif_last": 8, "xmp": 3}
    for name, code in expected.items():
        assert pillow_orientation(pngs[name]) == code, name
        assert exif_orientation(pngs[name]) == code, name
    assert [name for name in pngs if png_without_exif(pngs[name])] == ["opencv", "depth", "text"]
    assert exif_orientation(pngs["truncated"]) == 1  # unsure from the chunks: Pillow's answer, as before


def test_a_png_turned_by_its_exif_is_read_upright(pngs):
    stored = cv2.imread(str(pngs["opencv"]), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(read_image(pngs["exif_last"]), np.rot90(stored, 1))  # 8: 90 deg counter-clockwise
    assert np.array_equal(read_image(pngs["depth"]), cv2.imread(str(pngs["depth"]), cv2.IMREAD_UNCHANGED))
