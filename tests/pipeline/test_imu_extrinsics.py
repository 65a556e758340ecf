"""Camera-IMU rotation: parsing what users write, estimating it from data, and the phone case
through the real CLI (issue 16)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.drivers.extrinsics import axis_letters, parse_imu_rotation
from uareme_fusion.errors import ConfigError
from uareme_fusion.pipeline.imu_rotation_check import estimate_imu_rotation

PHONE_R_CI = np.diag([1.0, -1.0, -1.0])
"""IMU x right, y up, z backwards w.r.t. the OpenCV camera (x right, y down, z forward)."""


@pytest.mark.parametrize("text", ["android", "ios", "rub", "RUB", "1,0,0, 0,-1,0, 0,0,-1", "[1 0 0 0 -1 0 0 0 -1]",
                                  "1,0,0,0"])
def test_phone_conventions_parse_to_the_same_rotation(text):
    np.testing.assert_allclose(parse_imu_rotation(text), PHONE_R_CI, atol=1e-12)


def test_axis_letters_map_imu_axes_to_camera_directions():
    R = parse_imu_rotation("flu")  # ROS body: x forward, y left, z up
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 0, 1])
    np.testing.assert_allclose(R @ [0, 1, 0], [-1, 0, 0])
    np.testing.assert_allclose(R @ [0, 0, 1], [0, -1, 0])
    np.testing.assert_allclose(parse_imu_rotation("rdf"), np.eye(3))
    assert axis_letters(R) == ("flu", 0.0)
    tilted = R @ Rotation.from_euler("x", 7, degrees=True).as_matrix()
    letters, off_deg = axis_letters(tilted)
    assert letters == "flu" and off_deg == pytest.approx(7.0)


def test_kalibr_camchain_gives_the_rotation_of_T_cam_imu(tmp_path):
    R = Rotation.from_euler("xyz", [10, -20, 95], degrees=True).as_matrix()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [0.01, 0.02, -0.03]
    path = tmp_path / "camchain-imucam.yaml"
    rows = "".join(f"  - {row.tolist()}\n" for row in T)
    path.write_text("cam0:\n  T_cam_imu:\n" + rows + "  timeshift_cam_imu: 0.0\n")
    np.testing.assert_allclose(parse_imu_rotation(str(path)), R, atol=1e-12)


@pytest.mark.parametrize("text, words", [("rrd", "repeat an axis"), ("rdb", "left-handed"),
                                         ("1,2,3", "expected one of"), ("1,0,0, 0,1,0, 0,0,-1", "reflection"),
                                         ("2,0,0, 0,1,0, 0,0,1", "not orthonormal"), ("0,0,0,2", "norm 1"),
                                         ("missing.yaml", "missing.yaml")])
def test_bad_rotations_are_one_config_error_naming_the_option(text, words):
    with pytest.raises(ConfigError, match="--imu-rotation") as err:
        parse_imu_rotation(text)
    assert words in str(err.value)


def test_estimate_recovers_rotation_and_gyro_bias_from_noisy_pairs():
    rng = np.random.default_rng(4)
    R_ci = Rotation.from_euler("zyx", [80, -30, 170], degrees=True)
    bias = np.array([0.01, -0.03, 0.076])
    dt = np.full(300, 1 / 30)
    phi_c = rng.normal(0, 0.03, (300, 3))                       # camera turns between frames, rad
    phi_i = R_ci.inv().apply(phi_c) + bias * dt[:, None]        # what the biased gyro integrates to
    phi_c_noisy = phi_c + rng.normal(0, 0.001, phi_c.shape)
    est = estimate_imu_rotation(phi_i, phi_c_noisy, dt)
    error_deg = np.degrees((Rotation.from_matrix(est["R_ci"]) * R_ci.inv()).magnitude())
    assert error_deg < 0.5 and est["uncertainty_deg"] < 0.5
    np.testing.assert_allclose(est["gyro_bias_rad_s"], bias, atol=0.01)


def _run(args, exit_code=0):
    result = CliRunner().invoke(app, args)
    assert result.exit_code == exit_code, result.output
    return result.output


@pytest.fixture(scope="module")
def phone_sequence(tmp_path_factory):
    """A simulated room walk without its IMU, and that IMU written twice: in camera axes and in a
    phone's axes (`v_i = R_ci^T v_c`)."""
    root = tmp_path_factory.mktemp("phone")
    _run(["simulate", "room", "--frames", "75", "--size", "128x96", "--out", str(root / "seq")])
    imu_csv = root / "seq" / "imu0" / "data.csv"
    header = imu_csv.read_text().splitlines()[0]
    data = np.loadtxt(imu_csv, delimiter=",", comments="#")
    imu_csv.unlink()
    (root / "seq" / "imu0").rmdir()
    for name, R_ci in (("camera.csv", np.eye(3)), ("phone.csv", PHONE_R_CI)):
        rows = data.copy()
        rows[:, 1:4], rows[:, 4:7] = data[:, 1:4] @ R_ci, data[:, 4:7] @ R_ci  # row form of R_ci^T v_c
        np.savetxt(root / name, rows, delimiter=",", fmt=["%d"] + ["%.10f"] * 6, header=header[1:], comments="#")
    return root


def _eval(root, imu, *extra, exit_code=0):
    output = _run(["eval", str(root / "seq"), "--imu", str(root / imu), "--out", str(root / f"out_{imu}"), "--force",
                   *extra], exit_code)
    return json.loads((root / f"out_{imu}" / "summary.json").read_text()), output


@pytest.fixture(scope="module")
def camera_run(phone_sequence):
    """(summary, output) of `eval` with the IMU log in camera axes: the reference of the tests below."""
    return _eval(phone_sequence, "camera.csv")


@pytest.mark.slow
def test_phone_imu_axes_with_imu_rotation_match_the_camera_axes_case(phone_sequence, camera_run, tmp_path):
    camera, camera_out = camera_run
    phone, phone_out = _eval(phone_sequence, "phone.csv", exit_code=2)  # refused: vision and gyro disagree
    config = tmp_path / "run.yaml"
    config.write_text("imu_rotation: android\nimu_time_offset_s: 0.0\n")
    fixed, fixed_out = _eval(phone_sequence, "phone.csv", "--config", str(config))
    fixed_cli, _ = _eval(phone_sequence, "phone.csv", "--imu-rotation", "rub")
    assert camera["tilt_deg"]["mean"] < 2.0
    for run in (fixed, fixed_cli):
        assert run["tilt_deg"]["mean"] == pytest.approx(camera["tilt_deg"]["mean"], abs=0.05)
        assert run["tilt_deg"]["max"] == pytest.approx(camera["tilt_deg"]["max"], abs=0.2)
        assert run["stopped"] == "end" and not run["imu_rotation_estimate"]["refused_to_fuse"]
    # without the rotation the run is refused once the data shows the disagreement (about a second in),
    # with one error line naming the phone convention and the option; never fused to the end silently
    assert phone["stopped"] == "input_error" and phone["estimates"] < camera["estimates"]
    assert phone["imu_rotation_estimate"]["refused_to_fuse"] and phone["warnings"] == []
    errors = [line for line in phone_out.splitlines() if "error" in line]
    assert "--imu-rotation rub" in phone["error"] and "android" in phone["error"] and len(errors) >= 1
    assert "warning" not in camera_out and "warning" not in fixed_out
    # the data's own estimate of R_ci, in summary.json
    est = phone["imu_rotation_estimate"]
    assert est["observable"] and est["nearest_axis_letters"] == "rub"
    assert np.degrees(Rotation.from_matrix(np.array(est["R_ci"]).T @ PHONE_R_CI).magnitude()) < 5.0
    assert fixed["imu_rotation_estimate"]["angle_to_used_deg"] < 5.0


@pytest.mark.slow
def test_imu_time_offset_moves_imu_stamps_onto_the_camera_clock(phone_sequence, camera_run):
    """The offset is added to IMU stamps: a log shifted by -0.05 s is put back by +0.05 s."""
    shifted = phone_sequence / "camera_late.csv"
    rows = np.loadtxt(phone_sequence / "camera.csv", delimiter=",", comments="#")
    rows[:, 0] -= 50_000_000
    np.savetxt(shifted, rows, delimiter=",", fmt=["%d"] + ["%.10f"] * 6)
    reference, _ = camera_run
    fixed, _ = _eval(phone_sequence, "camera_late.csv", "--imu-time-offset-s", "0.05")
    assert fixed["config"]["imu_time_offset_s"] == 0.05
    assert fixed["tilt_deg"]["mean"] == pytest.approx(reference["tilt_deg"]["mean"], abs=0.05)


@pytest.mark.parametrize("args, words", [(["--imu-rotation", "xyz"], "imu_rotation: Value error, expected one of"),
                                         (["--imu-rotation", "rrd"], "repeat an axis"),
                                         (["--imu-time-offset-s", "nan"], "imu_time_offset_s")])
def test_bad_imu_geometry_options_are_one_error_line_before_the_run(tmp_path, args, words):
    result = CliRunner().invoke(app, ["run", "sim:room", "--max-frames", "2", "--out", str(tmp_path / "o"), *args])
    assert result.exit_code == 2 and words in result.output, result.output
    assert not (tmp_path / "o" / "summary.json").exists()


def test_warning_names_letters_near_an_axis_convention_and_a_quaternion_otherwise():
    from uareme_fusion.pipeline.imu_rotation_check import ImuRotationCheck

    check = ImuRotationCheck(np.eye(3))
    base = {"observable": True, "quat_xyzw": [0.0, 0.0, 0.2588, 0.9659]}
    assert check.warning({**base, "angle_to_used_deg": 5.0, "nearest_axis_letters": "rdf",
                          "nearest_axis_letters_deg": 5.0}) is None
    near = check.warning({**base, "angle_to_used_deg": 92.0, "nearest_axis_letters": "flu",
                          "nearest_axis_letters_deg": 3.0})
    assert "--imu-rotation flu" in near and "(ros)" in near
    far = check.warning({**base, "angle_to_used_deg": 45.0, "nearest_axis_letters": "rdf",
                         "nearest_axis_letters_deg": 45.0})
    assert "--imu-rotation 0.0000,0.0000,0.2588,0.9659" in far
    assert check.warning({**base, "observable": False, "angle_to_used_deg": 180.0}) is None
