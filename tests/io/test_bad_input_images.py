"""Bad input for the image and array readers: normal maps (.npy/.npz/PNG), depth PNGs, depth normals.

Every case asserts an `InputError` whose message names the file (or source) and the problem, or the
documented recovery (NaN/Inf normals and kappa are loaded as they are and counted invalid by the
solver). Nothing here decodes a large image: oversized headers are refused before decoding.
"""

from __future__ import annotations

import re
import struct

import cv2
import numpy as np
import pytest

from uareme_fusion import solve_manhattan
from uareme_fusion.errors import ConfigError, InputError
from uareme_fusion.io.images import MAX_IMAGE_PIXELS, image_size, read_image
from uareme_fusion.io.normal_maps import load_normal_map
from uareme_fusion.normals.depth import DepthNormals, DepthNormalsConfig, read_depth_png

from helpers import png_bytes  # pytest puts tests/ on sys.path

RNG = np.random.default_rng(0)
NORMALS = RNG.normal(size=(12, 16, 3)).astype(np.float32)
RGB8 = RNG.integers(0, 256, size=(12, 16, 3), dtype=np.uint8)
DEPTH16 = RNG.integers(500, 5000, size=(12, 16), dtype=np.uint16)
K = np.array([[20.0, 0.0, 8.0], [0.0, 20.0, 6.0], [0.0, 0.0, 1.0]])


def jpeg_with_size(width: int, height: int) -> bytes:
    """A valid small JPEG whose SOF0 marker is rewritten to declare width x height."""
    ok, buf = cv2.imencode(".jpg", RGB8)
    data = bytearray(buf.tobytes())
    pos = data.index(b"\xff\xc0")
    data[pos + 5 : pos + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def encoded(ext: str, image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(ext, image)
    assert ok
    return buf.tobytes()


def write(path, content):
    if isinstance(content, np.ndarray):
        with open(path, "wb") as fh:  # a file handle: numpy must not append its own extension
            np.save(fh, content)
    elif isinstance(content, dict):
        with open(path, "wb") as fh:
            np.savez(fh, **content)
    elif isinstance(content, str):
        path.write_text(content)
    else:
        path.write_bytes(content)
    return path


GOOD_PNG = encoded(".png", RGB8)
GOOD_JPG = encoded(".jpg", RGB8)

# (file name, content, regex the message must match); every message must also name the file.
NORMAL_MAP_CASES = [
    ("zero_bytes.png", b"", "empty file"),
    ("text.png", "hello, I am text", "not a format OpenCV reads.*hello"),
    ("truncated_half.png", GOOD_PNG[: len(GOOD_PNG) // 2], "corrupt or truncated"),
    ("truncated_header.png", GOOD_PNG[:20], "corrupt or truncated"),
    ("only_signature.png", GOOD_PNG[:8], "corrupt or truncated"),
    ("zeroed_data.png", GOOD_PNG[:40] + bytes(len(GOOD_PNG) - 40), "corrupt or truncated"),
    ("lossy.jpg", GOOD_JPG, r"unsupported normal map format '\.jpg'"),
    ("jpeg_renamed.png", GOOD_JPG[:30], "corrupt or truncated|cannot decode"),
    ("huge_header.png", png_bytes(100_000, 100_000), "100000 x 100000 pixels, more than the limit"),
    ("huge_but_under_opencv_limit.png", png_bytes(30_000, 30_000), "30000 x 30000 pixels, more than the limit"),
    ("wide.png", png_bytes(1 << 24, 8), "pixels, more than the limit"),
    ("jpeg_huge_header.png", jpeg_with_size(60_000, 60_000), "60000 x 60000 pixels"),
    ("zero_width.png", png_bytes(0, 10), "zero side"),
    ("grayscale.png", encoded(".png", RGB8[..., 0]), "3 colour channels"),
    ("grayscale16.png", encoded(".png", RGB8[..., 0].astype(np.uint16) * 257), "3 colour channels"),
    ("float_tiff.tiff", encoded(".tiff", RGB8.astype(np.float32) / 255), "8- or 16-bit"),
    ("folder.png", None, "is a folder"),
    ("missing.png", "MISSING", "no such file"),
    ("map.bmp", GOOD_PNG, "unsupported normal map format '.bmp'"),
    ("noext", GOOD_PNG, "unsupported normal map format ''"),
    # .npy
    ("ints.npy", NORMALS.astype(np.int16), "floating-point normals.*int16"),
    ("bools.npy", NORMALS > 0, "floating-point normals.*bool"),
    ("complex.npy", NORMALS.astype(np.complex64), "floating-point normals.*complex64"),
    ("strings.npy", np.full((4, 4, 3), "a"), "floating-point normals"),
    ("structured.npy", np.zeros((4, 4, 3), dtype=[("x", "f4")]), "floating-point normals"),
    ("zero_rows.npy", np.zeros((0, 4, 3), np.float32), r"\(0, 4, 3\)"),
    ("zero_cols.npy", np.zeros((4, 0, 3), np.float32), r"\(4, 0, 3\)"),
    ("flat.npy", np.zeros((16, 3), np.float32), r"\(H, W, 3\) or \(H, W, 4\), got \(16, 3\)"),
    ("two_channels.npy", np.zeros((4, 4, 2), np.float32), r"got \(4, 4, 2\)"),
    ("five_channels.npy", np.zeros((4, 4, 5), np.float32), r"got \(4, 4, 5\)"),
    ("batch.npy", np.zeros((2, 4, 4, 3), np.float32), r"got \(2, 4, 4, 3\)"),
    ("scalar.npy", np.array(1.0, np.float32), r"got \(\)"),
    ("empty.npy", b"", "not a readable .npy array"),
    ("text.npy", "just text", "not a readable .npy array"),
    ("truncated_header.npy", b"\x93NUMPY\x01\x00\x76\x00{'descr'", "not a readable .npy array"),
    ("truncated_data.npy", None, "not a readable .npy array|file holds less"),
    ("huge_header.npy", None, r"declares shape \(100000, 100000, 3\).*limit"),
    ("lying_header.npy", None, r"declares shape \(400, 400, 3\).*file holds less"),
    ("objects.npy", None, "Python objects"),
    ("npz_named.npy", {"normals": NORMALS}, r"\.npz archive \(zip\), not an \.npy array"),
    # .npz
    ("npy_named.npz", NORMALS, "not a zip file.*rename it to .npy"),
    ("text.npz", "not a zip", "not a readable .npz archive"),
    ("truncated.npz", None, "not a readable .npz archive"),
    ("no_normals_key.npz", {"n": NORMALS}, r"named 'normals'.*found \['n'\]"),
    ("empty_archive.npz", {}, r"named 'normals'.*found \[\]"),
    ("kappa_wrong_shape.npz", {"normals": NORMALS, "kappa": np.ones((3, 3))},
     r"kappa has shape \(3, 3\), expected \(12, 16\)"),
    ("kappa_transposed.npz", {"normals": NORMALS, "kappa": np.ones((16, 12))}, r"kappa has shape \(16, 12\)"),
    ("kappa_strings.npz", {"normals": NORMALS, "kappa": np.full((12, 16), "x")}, "kappa as real numbers"),
    ("kappa_objects.npz", None, "Python objects"),
    ("normals_int.npz", {"normals": NORMALS.astype(np.int32)}, "floating-point normals.*int32"),
    ("normals_2d.npz", {"normals": np.zeros((5, 3))}, r"got \(5, 3\)"),
    ("huge_member.npz", None, r"declares shape \(100000, 100000, 3\)"),
]


def make_special(path, name):
    if name == "folder.png":
        path.mkdir()
    elif name == "truncated_data.npy":
        np.save(path, NORMALS)
        path.write_bytes(path.read_bytes()[:-100])
    elif name in ("huge_header.npy", "lying_header.npy"):
        shape = (100_000, 100_000, 3) if name.startswith("huge") else (400, 400, 3)
        with open(path, "wb") as fh:
            np.lib.format.write_array_header_1_0(fh, {"descr": "<f4", "fortran_order": False, "shape": shape})
            fh.write(bytes(64))
    elif name == "objects.npy":
        np.save(path, np.array([[[None, 1, "a"]]], dtype=object), allow_pickle=True)
    elif name == "truncated.npz":
        np.savez(path, normals=NORMALS)
        path.write_bytes(path.read_bytes()[:200])
    elif name == "kappa_objects.npz":
        np.savez(path, normals=NORMALS, kappa=np.full((12, 16), None, dtype=object))
    elif name == "huge_member.npz":
        import io
        import zipfile

        buf = io.BytesIO()
        header = {"descr": "<f4", "fortran_order": False, "shape": (100_000, 100_000, 3)}
        np.lib.format.write_array_header_1_0(buf, header)
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("normals.npy", buf.getvalue() + bytes(64))


@pytest.mark.parametrize("name, content, message", NORMAL_MAP_CASES, ids=[c[0] for c in NORMAL_MAP_CASES])
def test_bad_normal_map_files_name_the_file_and_the_problem(tmp_path, name, content, message):
    path = tmp_path / name
    if content is None:
        make_special(path, name)
    elif not (isinstance(content, str) and content == "MISSING"):
        write(path, content)
    with pytest.raises(InputError) as info:
        load_normal_map(path)
    text = str(info.value)
    assert str(path) in text, text
    assert re.search(message, text), text


# Awkward but valid normal maps: loaded, and the solver ignores and counts the pixels it cannot use.
ROWS, COLS = np.meshgrid(np.arange(12), np.arange(16), indexing="ij")
VALID_CASES = [
    ("rgba.png", lambda p: cv2.imwrite(str(p), np.dstack([RGB8, RGB8[..., :1]])), 0),
    ("sixteen_bit.png", lambda p: cv2.imwrite(str(p), RGB8.astype(np.uint16) * 257), 0),
    ("one_pixel.png", lambda p: cv2.imwrite(str(p), np.array([[[255, 128, 128]]], np.uint8)), 0),
    ("jpeg.png", lambda p: p.write_bytes(GOOD_JPG), 0),
    ("float16.npy", lambda p: np.save(p, NORMALS.astype(np.float16)), 0),
    ("float64_big_endian.npy", lambda p: np.save(p, NORMALS.astype(">f8")), 0),
    ("some_nan.npy", lambda p: np.save(p, np.where(ROWS[..., None] < 3, np.nan, NORMALS)), 3 * 16),
    ("some_inf.npy", lambda p: np.save(p, np.where(COLS[..., None] < 2, np.inf, NORMALS)), 2 * 12),
    ("zero_vectors.npy", lambda p: np.save(p, np.where(ROWS[..., None] == 0, 0.0, NORMALS)), 16),
    ("nan_kappa.npy", lambda p: np.save(p, np.dstack([NORMALS, np.where(ROWS < 4, np.nan, 1)]).astype(np.float32)), 64),
    ("negative_kappa.npz", lambda p: np.savez(p, normals=NORMALS, kappa=np.where(ROWS < 6, -1.0, 1.0)), 6 * 16),
    ("integer_kappa.npz", lambda p: np.savez(p, normals=NORMALS, kappa=np.ones((12, 16), np.int64)), 0),
    ("kappa_overrides_channel.npz",
     lambda p: np.savez(p, normals=np.dstack([NORMALS, 0 * ROWS]).astype(np.float32), kappa=1 + 0 * ROWS), 0),
]


@pytest.mark.parametrize("name, make, n_invalid", VALID_CASES, ids=[c[0] for c in VALID_CASES])
def test_awkward_valid_maps_load_and_bad_pixels_are_counted(tmp_path, name, make, n_invalid):
    path = tmp_path / name
    make(path)
    nm = load_normal_map(path)
    assert nm.normals.dtype == np.float32 and nm.normals.ndim == 3 and nm.normals.shape[2] == 3
    assert nm.kappa.shape == nm.normals.shape[:2]
    result = solve_manhattan(nm)
    assert result.n_invalid == n_invalid
    assert result.n_valid + result.n_invalid == nm.normals.shape[0] * nm.normals.shape[1]
    np.testing.assert_allclose(result.R_cm.T @ result.R_cm, np.eye(3), atol=1e-9)


@pytest.mark.parametrize("fill", [np.nan, np.inf, 0.0], ids=["all_nan", "all_inf", "all_zero"])
def test_maps_without_one_usable_pixel_say_so(tmp_path, fill):
    path = tmp_path / "bad.npy"
    np.save(path, np.full((5, 6, 3), fill, np.float32))
    with pytest.raises(InputError, match=r"No valid normals in a map of shape \(5, 6, 3\): all 30 pixels"):
        solve_manhattan(load_normal_map(path))


def test_unknown_frame_names_the_choices(tmp_path):
    np.save(tmp_path / "n.npy", NORMALS)
    with pytest.raises(InputError, match="Unknown normal frame 'ros'; use one of opencv, opengl"):
        load_normal_map(tmp_path / "n.npy", frame="ros")


# ---------------------------------------------------------------- image header and read_image


@pytest.mark.parametrize(
    "content, size",
    [(png_bytes(640, 480), (640, 480)), (jpeg_with_size(1234, 567), (1234, 567)), (GOOD_PNG, (16, 12)),
     (GOOD_JPG, (16, 12)), (b"GIF89a....", None), (b"\x89PNG\r\n\x1a\n", None)],
    ids=["png", "jpeg_rewritten", "png_real", "jpeg_real", "gif", "png_signature_only"],
)
def test_image_size_reads_headers_without_decoding(tmp_path, content, size):
    path = write(tmp_path / "img", content)
    assert image_size(path) == size


def test_read_image_limit_is_checked_before_decoding(tmp_path):
    side = int(np.sqrt(MAX_IMAGE_PIXELS)) + 1
    path = write(tmp_path / "big.png", png_bytes(side, side))
    with pytest.raises(InputError, match=f"{side} x {side} pixels.*refusing to decode"):
        read_image(path, what="a test image")


# ---------------------------------------------------------------- depth PNGs

DEPTH_CASES = [
    ("missing.png", "MISSING", {}, "depth image not found"),
    ("zero_bytes.png", b"", {}, "empty file"),
    ("text.png", "depth, honest", {}, "not a readable image"),
    ("truncated.png", encoded(".png", DEPTH16)[:60], {}, "corrupt or truncated"),
    ("eight_bit.png", encoded(".png", (DEPTH16 % 256).astype(np.uint8)), {}, "expected 16-bit depth.*uint8"),
    ("colour16.png", encoded(".png", np.dstack([DEPTH16] * 3)), {},
     r"single-channel depth image, got shape \(12, 16, 3\)"),
    ("rgba16.png", encoded(".png", np.dstack([DEPTH16] * 4)), {}, r"single-channel.*\(12, 16, 4\)"),
    ("jpeg.png", GOOD_JPG, {}, "single-channel|16-bit"),
    ("float.tiff", encoded(".tiff", DEPTH16.astype(np.float32)), {}, "expected 16-bit depth.*float32"),
    ("wrong_size.png", encoded(".png", DEPTH16), {"expected_shape": (480, 640)},
     r"size \(480, 640\) \(H, W\), got \(12, 16\)"),
    ("transposed.png", encoded(".png", DEPTH16), {"expected_shape": (16, 12)}, r"size \(16, 12\)"),
    ("zero_unit.png", encoded(".png", DEPTH16), {"unit_m": 0.0}, "depth unit must be > 0"),
    ("negative_unit.png", encoded(".png", DEPTH16), {"unit_m": -1e-3}, "depth unit must be > 0"),
    ("nan_unit.png", encoded(".png", DEPTH16), {"unit_m": float("nan")}, "depth unit must be > 0"),
    ("huge.png", png_bytes(50_000, 50_000, colour_type=0, bit_depth=16), {}, "50000 x 50000 pixels"),
]


@pytest.mark.parametrize("name, content, kwargs, message", DEPTH_CASES, ids=[c[0] for c in DEPTH_CASES])
def test_bad_depth_pngs_name_the_file(tmp_path, name, content, kwargs, message):
    path = tmp_path / name
    if not (isinstance(content, str) and content == "MISSING"):
        write(path, content)
    kwargs = {"unit_m": 1e-3, **kwargs}
    with pytest.raises(InputError) as info:
        read_depth_png(path, **kwargs)
    assert str(path) in str(info.value) and re.search(message, str(info.value)), str(info.value)


# ---------------------------------------------------------------- depth normals

PLANE = np.full((20, 24), 2.0, np.float32)

ESTIMATE_CASES = [
    ("no_K", PLANE, None, "need camera intrinsics K"),
    ("K_2x2", PLANE, np.eye(2), r"finite \(3, 3\) matrix, got shape \(2, 2\)"),
    ("K_flat", PLANE, np.ones(9), r"got shape \(9,\)"),
    ("K_nan", PLANE, np.where(np.eye(3) > 0, np.nan, 0.0), "NaN or infinite entries"),
    ("K_inf", PLANE, np.full((3, 3), np.inf), "NaN or infinite entries|fx > 0"),
    ("K_strings", PLANE, [["a", "b", "c"]] * 3, "matrix of numbers"),
    ("K_ragged", PLANE, [[1, 2], [3]], "matrix of numbers"),
    ("K_zero_fx", PLANE, np.diag([0.0, 20.0, 1.0]), "fx > 0 and fy > 0"),
    ("K_negative_fx", PLANE, np.diag([-20.0, 20.0, 1.0]), "fx > 0 and fy > 0, got fx = -20"),
    ("K_negative_fy", PLANE, np.diag([20.0, -20.0, 1.0]), "fy = -20 < 0.*flip_y_rotation"),
    ("depth_1d", np.ones(30, np.float32), K, r"shape \(H, W\).*got \(30,\)"),
    ("depth_3d", np.ones((20, 24, 1), np.float32), K, r"got \(20, 24, 1\)"),
    ("depth_scalar", np.float32(2.0), K, r"got \(\)"),
    ("depth_too_small", np.ones((5, 40), np.float32), K, r"at least 9 px each way, got \(5, 40\)"),
    ("depth_empty", np.zeros((0, 0), np.float32), K, r"got \(0, 0\)"),
    ("depth_uint16", DEPTH16.repeat(2, 0).repeat(2, 1), K, "float metres, got uint16.*read_depth_png"),
    ("depth_bool", np.ones((20, 24), bool), K, "float metres, got bool"),
    ("depth_complex", np.ones((20, 24), np.complex64), K, "float metres, got complex64"),
    ("depth_ragged_list", [[1.0, 2.0], [3.0]], K, "expected a depth map"),
]


@pytest.mark.parametrize("name, depth, K_, message", ESTIMATE_CASES, ids=[c[0] for c in ESTIMATE_CASES])
def test_bad_depth_or_intrinsics_name_the_source(name, depth, K_, message):
    with pytest.raises(InputError) as info:
        DepthNormals().estimate(depth, K_, source="frame 7")
    assert str(info.value).startswith("frame 7: ") and re.search(message, str(info.value)), str(info.value)


@pytest.mark.parametrize(
    "depth, expected_valid",
    [(np.full((20, 24), np.nan, np.float32), 0), (np.full((20, 24), np.inf, np.float32), 0),
     (np.full((20, 24), -2.0, np.float32), 0), (np.zeros((20, 24), np.float32), 0),
     (np.full((20, 24), 1e30, np.float64), 0), (PLANE.astype(np.float16), None)],
    ids=["all_nan", "all_inf", "negative", "zeros", "overflowing_float64", "float16_plane"],
)
def test_unusable_depth_gives_kappa_zero_not_nan(depth, expected_valid):
    nm = DepthNormals().estimate(depth, K)
    assert np.all(np.isfinite(nm.normals)) and np.all(np.isfinite(nm.kappa)) and np.all(nm.kappa >= 0)
    if expected_valid is None:  # same as the float32 plane
        expected_valid = int(np.count_nonzero(DepthNormals().estimate(PLANE, K).kappa > 0))
        assert expected_valid > 0
    assert int(np.count_nonzero(nm.kappa > 0)) == expected_valid


@pytest.mark.parametrize(
    "kwargs, message",
    [({"window_px": 4}, "odd integer >= 3"), ({"window_px": 1}, "odd integer >= 3"),
     ({"min_valid_fraction": 0.0}, r"min_valid_fraction must be in \(0, 1\]"),
     ({"min_valid_fraction": float("nan")}, "min_valid_fraction"), ({"stride_px": 0}, "stride_px must be >= 1"),
     ({"min_depth_m": 5.0, "max_depth_m": 1.0}, "min_depth_m < max_depth_m"),
     ({"noise_floor_m": -1.0}, "noise_floor_m must be >= 0"),
     ({"noise_quadratic_m_per_m2": 0.0, "noise_floor_m": 0.0}, "needs noise_quadratic"),
     ({"kappa_max": float("nan")}, "kappa_max must be > 0"),
     ({"max_residual_ratio": float("nan")}, "max_residual_ratio")],
    ids=["even_window", "tiny_window", "zero_fraction", "nan_fraction", "zero_stride", "depth_range_reversed",
         "negative_floor", "no_noise_model", "nan_kappa_max", "nan_residual_ratio"],
)
def test_bad_depth_normals_config_names_the_field(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        DepthNormalsConfig(**kwargs)
