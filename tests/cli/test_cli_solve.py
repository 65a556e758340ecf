"""`uareme-fusion solve`: bring-your-own normals through the command line."""

import json

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.io.normal_maps import load_normal_map, normals_to_rgb
from uareme_fusion.rotations import angle_between, exp_so3, matrix_from_quat_xyzw, nearest_symmetric
from uareme_fusion.sim.normal_maps import manhattan_normal_map

runner = CliRunner()
R_TRUE = exp_so3([0.2, -0.5, 0.1])


@pytest.fixture(scope="module")
def normal_map():
    return manhattan_normal_map(R_TRUE, np.random.default_rng(0), height=96, width=128, noise_deg=4.0)


def solve_json(path, *extra):
    result = runner.invoke(app, ["solve", str(path), "--json", *extra])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def assert_recovers_truth(report, tol_deg=0.5):
    R_cm = matrix_from_quat_xyzw(report["quat_cm_xyzw"])
    np.testing.assert_allclose(R_cm, report["R_cm"], atol=1e-6)
    R_near, _ = nearest_symmetric(R_cm, R_TRUE)
    assert np.degrees(angle_between(R_near, R_TRUE)) < tol_deg


def test_npz_with_kappa(tmp_path, normal_map):
    path = tmp_path / "map.npz"
    np.savez(path, normals=normal_map.normals, kappa=normal_map.kappa)
    report = solve_json(path)
    assert_recovers_truth(report)
    assert report["shape"] == [96, 128]
    assert np.array(report["cov_rad2"]).shape == (3, 3)
    assert report["n_valid"] == 96 * 128 and report["n_invalid"] == 0
    assert report["solve_ms"] > 0
    # Up candidate is a unit Manhattan axis near image up (-y).
    up = np.array(report["up_candidate_c"])
    assert up @ [0, -1, 0] > 0 and np.linalg.norm(up) == pytest.approx(1.0)


def test_npy_four_channels_and_png(tmp_path, normal_map):
    four = np.concatenate([normal_map.normals, normal_map.kappa[..., None]], axis=-1)
    np.save(tmp_path / "map.npy", four)
    assert_recovers_truth(solve_json(tmp_path / "map.npy"))
    cv2.imwrite(str(tmp_path / "map.png"), normals_to_rgb(normal_map.normals)[..., ::-1])
    assert_recovers_truth(solve_json(tmp_path / "map.png"), tol_deg=1.0)


def test_opengl_frame_is_converted(tmp_path, normal_map):
    np.save(tmp_path / "gl.npy", normal_map.normals * np.array([1, -1, -1], np.float32))
    assert_recovers_truth(solve_json(tmp_path / "gl.npy", "--frame", "opengl"))
    loaded = load_normal_map(tmp_path / "gl.npy", frame="opengl")
    np.testing.assert_allclose(loaded.normals, normal_map.normals)


def test_human_readable_output(tmp_path, normal_map):
    np.save(tmp_path / "map.npy", normal_map.normals)
    result = runner.invoke(app, ["solve", str(tmp_path / "map.npy")])
    assert result.exit_code == 0
    assert "quaternion R_cm" in result.stdout and "up candidate" in result.stdout


def write_garbage(path):
    path.write_bytes(b"this is not a normal map")


@pytest.mark.parametrize(
    "name, make, message",
    [
        ("missing.npy", None, "no such file"),
        ("corrupt.png", write_garbage, "cannot decode"),
        ("corrupt.npy", write_garbage, "not a readable .npy"),
        ("corrupt.npz", write_garbage, "not a readable .npz"),
        ("map.txt", write_garbage, "unsupported normal map format"),
        ("gray.png", lambda p: cv2.imwrite(str(p), np.zeros((8, 8), np.uint8)), "3 colour channels"),
        ("wrong.npy", lambda p: np.save(p, np.zeros((8, 8, 2), np.float32)), r"\(8, 8, 2\)"),
        ("ints.npy", lambda p: np.save(p, np.zeros((8, 8, 3), np.int32)), "floating-point"),
        ("nokey.npz", lambda p: np.savez(p, foo=np.zeros((8, 8, 3))), "named 'normals'"),
        ("badkappa.npz", lambda p: np.savez(p, normals=np.ones((8, 8, 3)), kappa=np.ones((4, 4))), "kappa has shape"),
        ("nan.npy", lambda p: np.save(p, np.full((8, 8, 3), np.nan, np.float32)), "No valid normals"),
    ],
)
def test_bad_files_give_one_line_and_exit_2(tmp_path, name, make, message):
    path = tmp_path / name
    if make is not None:
        make(path)
    result = runner.invoke(app, ["solve", str(path), "--json"])
    assert result.exit_code == 2
    assert result.stdout == ""
    assert len(result.stderr.strip().splitlines()) == 1
    assert "Traceback" not in result.stderr
    import re

    assert re.search(message, result.stderr), result.stderr


def test_unknown_frame_option(tmp_path, normal_map):
    np.save(tmp_path / "map.npy", normal_map.normals)
    result = runner.invoke(app, ["solve", str(tmp_path / "map.npy"), "--frame", "ros"])
    assert result.exit_code == 2
    assert "Unknown normal frame 'ros'" in result.stderr
