"""The mistakes people make with IMU logs, through the real command line (`uareme_fusion.drivers.imu_checks`).

A synthetic EuRoC folder (imu0 + gt0) of an IMU turning in all three axes at rest is written with one
mistake at a time. Fixed mistakes (timestamps in us or ms, accel in g, accel columns first, gyro in
deg/s, the log repeated after itself) must print a warning, record it in summary.json and give the
same tilt error as the clean log; the others (two different recordings in one file, an IMU on another
clock than the video) must fail in one line naming the file, the column and the likely cause.
"""

from __future__ import annotations

import json
import re

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from uareme_fusion.cli import app

runner = CliRunner()
RATE_HZ = 200.0
SECONDS = 12.0
T0_NS = 1_403_715_523_912_140_000
HEADER = "#timestamp [ns],w_x [rad/s],w_y,w_z,a_x [m/s^2],a_y,a_z\n"


def turning_imu(seed: int = 0):
    """(t_ns (N,), gyro rad/s (N, 3), accel m/s^2 (N, 3), R_wi (N, 3, 3)): an IMU at rest turning smoothly."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(SECONDS * RATE_HZ) + 1) / RATE_HZ
    angles = np.column_stack([0.6 * np.sin(2 * np.pi * 0.13 * t), 0.4 * np.sin(2 * np.pi * 0.21 * t + 1.0),
                              0.8 * np.sin(2 * np.pi * 0.07 * t)])
    R_wi = Rotation.from_euler("zyx", angles)
    gyro = (R_wi[:-1].inv() * R_wi[1:]).as_rotvec() * RATE_HZ  # mean rate over each interval, body frame
    gyro = np.vstack([gyro[:1], gyro]) + rng.normal(0, 0.003, (len(t), 3))
    accel = R_wi.inv().apply([0.0, 0.0, 9.81]) + rng.normal(0, 0.05, (len(t), 3))
    t_ns = T0_NS + np.round(t * 1e9).astype(np.int64)
    return t_ns, gyro, accel, R_wi.as_matrix()


def write_log(path, t_ns, first, second, header=HEADER, stamp=str):
    rows = [f"{stamp(t)},{a[0]:.9g},{a[1]:.9g},{a[2]:.9g},{b[0]:.9g},{b[1]:.9g},{b[2]:.9g}"
            for t, a, b in zip(t_ns, first, second)]
    path.write_text(header + "\n".join(rows) + "\n")


EXPORT_HEADER = "t_s,gx,gy,gz,ax,ay,az\n"
"""A common export: column names without '#', timestamps in seconds with decimals."""


def euroc_folder(root, mistake: str):
    t_ns, gyro, accel, R_wi = turning_imu()
    mav0 = root / "mav0"
    (mav0 / "imu0").mkdir(parents=True)
    (mav0 / "gt0").mkdir()
    q = Rotation.from_matrix(R_wi).as_quat(scalar_first=True)
    (mav0 / "gt0" / "data.csv").write_text("#timestamp,px,py,pz,qw,qx,qy,qz\n" + "".join(
        f"{t},0,0,0,{w:.12f},{x:.12f},{y:.12f},{z:.12f}\n" for t, (w, x, y, z) in zip(t_ns, q)))
    log = mav0 / "imu0" / "data.csv"
    if mistake == "gyro_deg_s":
        write_log(log, t_ns, np.degrees(gyro), accel)
    elif mistake == "accel_g":
        write_log(log, t_ns, gyro, accel / 9.80665)
    elif mistake in ("time_us", "time_ms"):
        write_log(log, t_ns // (1000 if mistake == "time_us" else 1_000_000), gyro, accel)
    elif mistake == "time_float_s":
        write_log(log, t_ns, gyro, accel, EXPORT_HEADER, stamp=lambda t: f"{t * 1e-9:.6f}")
    elif mistake == "accel_first":
        write_log(log, t_ns, accel, gyro)
    elif mistake == "concatenated":
        write_log(log, np.r_[t_ns, t_ns], np.r_[gyro, gyro], np.r_[accel, accel])
    elif mistake == "two_recordings":
        write_log(log, np.r_[t_ns, t_ns[:500]], np.r_[gyro, -gyro[:500]], np.r_[accel, accel[:500]])
    else:
        write_log(log, t_ns, gyro, accel)
    return root


def eval_cli(folder, out):
    result = runner.invoke(app, ["eval", str(folder), "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").is_file() else None
    return result, summary


@pytest.fixture(scope="module")
def clean_tilt_deg(tmp_path_factory):
    root = tmp_path_factory.mktemp("clean")
    result, summary = eval_cli(euroc_folder(root / "seq", "none"), root / "out")
    assert result.exit_code == 0, result.output
    assert summary["input_fixes"] == [] and summary["mekf_preset"] == "imu_only"
    assert summary["tilt_deg"]["mean"] < 1.5
    return summary["tilt_deg"]["mean"]


FIXED = [
    ("gyro_deg_s", r"columns 2-4 \(w_x, w_y, w_z\).* as a gyro in deg/s does: converted to rad/s"),
    ("accel_g", r"columns 5-7 \(a_x, a_y, a_z\): median \|accel\| is 1, so the accelerometer is in g, not m/s\^2"),
    ("time_us", r"column 1 holds timestamps in us, not ns .* as us, 200 Hz\): converted to ns"),
    ("time_ms", r"column 1 holds timestamps in ms, not ns .* as ms, 200 Hz\): converted to ns"),
    ("time_float_s", r"column 1 holds timestamps in seconds with decimals, not integer ns \(as seconds, 200 Hz\): "
                     r"converted to ns"),
    ("accel_first", r"columns 2-4 .* read like an accelerometer .* accelerometer columns were written before the "
                    r"gyro's; swapped"),
    ("concatenated", r"2401 rows from row 2402 repeat earlier rows exactly \(the log concatenated with itself\?\): "
                     r"dropped"),
]


@pytest.mark.parametrize("mistake, message", FIXED, ids=[c[0] for c in FIXED])
def test_fixed_mistakes_warn_and_score_like_the_clean_log(tmp_path, clean_tilt_deg, mistake, message):
    result, summary = eval_cli(euroc_folder(tmp_path / "seq", mistake), tmp_path / "out")
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning: ")]
    assert len(warnings) == 1 and re.search(message, warnings[0]), result.stderr
    assert "data.csv" in warnings[0]
    assert len(summary["input_fixes"]) == 1 and re.search(message, summary["input_fixes"][0])
    assert summary["tilt_deg"]["mean"] == pytest.approx(clean_tilt_deg, abs=0.1)


def test_gyro_in_deg_s_without_rotation_to_tell_is_refused_when_out_of_range(tmp_path):
    t_ns = T0_NS + np.arange(1000, dtype=np.int64) * 5_000_000
    gyro = np.zeros((1000, 3))
    gyro[:, 2] = 90.0 * np.sin(np.linspace(0, 6, 1000))  # a yaw swing only: the accelerometer does not turn
    accel = np.tile([0.0, 0.0, 9.81], (1000, 1))
    write_log(tmp_path / "imu.csv", t_ns, gyro, accel)
    result = runner.invoke(app, ["run", str(tmp_path / "imu.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert re.fullmatch(r"error: .*imu.csv: columns 2-4 \(w_x, w_y, w_z\): the gyro reaches 90, beyond any "
                        r"gyro's range in rad/s .*: is it in deg/s\? Convert it to rad/s", result.stderr.strip())


def test_two_recordings_in_one_file_are_refused(tmp_path):
    result, _ = eval_cli(euroc_folder(tmp_path / "seq", "two_recordings"), tmp_path / "out")
    assert result.exit_code == 2
    assert re.fullmatch(r"error: .*imu0/data.csv: column 1 \(timestamp\): time goes back by 12 s at data row 2402 "
                        r"and 500 rows are earlier than rows before them: two recordings .* in one file\? Keep one "
                        r"of them", result.stderr.strip()), result.stderr


def test_imu_log_on_another_clock_than_the_video_is_refused(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(3):
        cv2.imwrite(str(frames / f"{i}.png"), np.full((24, 32, 3), 100, np.uint8))
    t_ns, gyro, accel, _ = turning_imu()
    write_log(tmp_path / "imu.csv", t_ns, gyro, accel)  # epoch ns; the frames run from 0 s
    result = runner.invoke(app, ["run", str(frames), "--imu", str(tmp_path / "imu.csv"), "--out",
                                 str(tmp_path / "out")])
    assert result.exit_code == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error")]
    assert len(errors) == 1 and re.search(
        r"imu.csv: column 1 \(timestamp\): the IMU samples span 1\.40372e\+09 to 1\.40372e\+09 s and the frames 0 to "
        r"0\.1 s, with no overlap: the IMU log is on another clock than the video", errors[0]), result.stderr
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["stopped"] == "input_error"


@pytest.mark.parametrize("unit, scale", [("ms", 1e-6), ("us", 1e-3)])
def test_timestamps_with_decimals_not_in_seconds_are_refused(tmp_path, unit, scale):
    """Decimals in ms or us (2.5 ms steps) are not seconds at an IMU rate: refused, nothing guessed."""
    t_ns, gyro, accel, _ = turning_imu()
    write_log(tmp_path / "imu.csv", t_ns - T0_NS + 2_500_500, gyro, accel, EXPORT_HEADER,
              stamp=lambda t: f"{t * scale:.3f}")
    result = runner.invoke(app, ["run", str(tmp_path / "imu.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    rate = {"ms": "0.2", "us": "0.0002"}[unit]
    assert result.stderr.strip() == (f"error: {tmp_path / 'imu.csv'}: column 1 (timestamp [ns]): holds numbers with "
                                     f"decimals; read as seconds they imply {rate} Hz, not an IMU rate of 20-4000 Hz: "
                                     "write integer nanoseconds")
    assert not (tmp_path / "out" / "summary.json").exists()
