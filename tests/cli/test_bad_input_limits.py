"""Inputs that used to hang or crash the tool (issue 15): YAML bombs and deep nesting, values that pass
type checks but overflow later, a huge float32 kappa, a camera index of 20 digits, a preset name
where an object was expected, pipes and link loops, a 48-megapixel photo. Each ends in one line and
the right exit status, or in a correct result."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import cv2
import numpy as np
import pytest

from uareme_fusion.backends.mekf import Mekf
from uareme_fusion.errors import InputError
from uareme_fusion.io.images import reduction_for
from uareme_fusion.io.paths import read_pipe_text
from uareme_fusion.formats.images import read_rgb
from uareme_fusion.pipeline.single_image import ANALYSIS_MAX_PIXELS
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.solver.manhattan import solve_manhattan
from helpers import cli, error_lines, subprocess_env

BILLION_LAUGHS = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{c}: &{c} [{', '.join([f'*{p}'] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi"))


@pytest.mark.parametrize("text, message", [
    (BILLION_LAUGHS, "is not valid YAML at line 2, column 8: found the alias *a: aliases are not allowed in "
                     "configuration files (write the value out)"),
    ("mekf: " + "[" * 5000 + "]" * 5000 + "\n", "is not valid YAML at line 1, column 38: nested more than 32 "
                                                "levels deep"),
    ("mekf: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n", "nested more than 32 levels deep"),
], ids=["billion_laughs", "deep_lists", "deep_mappings"])
def test_yaml_bombs_and_deep_nesting_are_one_line(tmp_path, text, message):
    (tmp_path / "bad.yaml").write_text(text)
    proc = cli("run", "sim:room", "--config", tmp_path / "bad.yaml", "--out", tmp_path / "out")
    assert proc.returncode == 2
    (line,) = error_lines(proc)
    assert line.startswith(f"error: {tmp_path / 'bad.yaml'}") and line.endswith(message)


def test_deeply_nested_scene_json_is_one_line(tmp_path):
    assert cli("simulate", "room", "--frames", "2", "--size", "64x48", "--out", tmp_path / "seq").returncode == 0
    (tmp_path / "seq" / "scene.json").write_text('{"a": ' + "[" * 100_000 + "]" * 100_000 + "}")
    proc = cli("run", tmp_path / "seq", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {tmp_path / 'seq' / 'scene.json'}: not a readable JSON file "
                                 "(nested too deeply)"]


@pytest.mark.parametrize("text, key, bound", [
    ("mekf:\n  gyro_noise_rad_s_sqrt_hz: 1.0e+300\n", "mekf.gyro_noise_rad_s_sqrt_hz", "less than or equal to 1"),
    ("mekf:\n  gravity_m_s2: 1.0e-300\n", "mekf.gravity_m_s2", "greater than or equal to 1"),
    ("backend: smoother\nsmoother:\n  between_std_rad: 1.0e-300\n", "smoother.between_std_rad",
     "greater than or equal to 0.000001"),
], ids=["noise_density", "gravity", "between_sigma"])
def test_values_outside_physical_ranges_name_the_key(tmp_path, text, key, bound):
    (tmp_path / "c.yaml").write_text(text)
    proc = cli("run", "sim:room", "--max-frames", "3", "--config", tmp_path / "c.yaml", "--out", tmp_path / "o")
    assert proc.returncode == 2
    (line,) = error_lines(proc)
    section, name = key.split(".")
    assert f"[{section}]: {name}: Input should be {bound}" in line
    assert not (tmp_path / "o" / "summary.json").exists() and not (tmp_path / "o" / "trajectory.tum").exists()


def test_a_huge_finite_float32_kappa_solves_like_a_normal_one(tmp_path):
    nm = manhattan_normal_map(np.eye(3), np.random.default_rng(0), height=24, width=32, noise_deg=3.0)
    normals = nm.normals.astype(np.float32)
    reference = solve_manhattan(normals, nm.kappa.astype(np.float32))
    huge = (nm.kappa / nm.kappa.max() * 3e38).astype(np.float32)
    result = solve_manhattan(normals, huge)
    assert np.abs(result.R_cm - reference.R_cm).max() < 1e-8
    assert np.allclose(result.cov, reference.cov, rtol=1e-5)
    np.savez(tmp_path / "huge.npz", normals=normals, kappa=huge)
    proc = cli("solve", tmp_path / "huge.npz", "--json")
    assert proc.returncode == 0, proc.stderr
    assert np.abs(np.array(json.loads(proc.stdout)["R_cm"]) - reference.R_cm).max() < 1e-8


def test_unscaled_kappa_gives_identical_results():
    """The rescale only happens when the moment sums overflow: ordinary maps give the same bits."""
    nm = manhattan_normal_map(np.eye(3), np.random.default_rng(1), height=24, width=32, noise_deg=3.0)
    a = solve_manhattan(nm.normals, nm.kappa)
    b = solve_manhattan(nm.normals, nm.kappa * 2.0 ** 20)
    assert np.array_equal(a.R_cm, b.R_cm) and np.allclose(a.cov, b.cov, rtol=1e-12)


def test_a_camera_index_of_twenty_digits_is_one_line(tmp_path):
    proc = cli("run", "webcam:99999999999999999999", "--out", tmp_path / "o")
    assert proc.returncode == 2
    assert error_lines(proc) == ["error: webcam:99999999999999999999: camera index 99999999999999999999 is out "
                                 "of range (0 to 9999)"]


def test_mekf_takes_a_preset_name():
    assert Mekf("vehicle").config.manhattan_yaw_rw_rad_per_sqrt_s == 0.5
    with pytest.raises(TypeError, match="expected a MekfConfig, a preset name .*vehicle.* or a YAML path, got dict"):
        Mekf({"gyro_noise_rad_s_sqrt_hz": 1e-3})


# ------------------------------------------------------------------------------ pipes and links
NO_FOCAL_SEARCH = "--cues normals"
"""For runs on the bare rgb/ folder (no intrinsics): the line cue would search the focal length on
each of the first 30 frames, seconds that the pipe tests below do not need."""


@pytest.fixture
def imu_csv(tmp_path):
    assert cli("simulate", "room", "--frames", "20", "--size", "64x48", "--out", tmp_path / "seq").returncode == 0
    return tmp_path / "seq"


@pytest.mark.slow
def test_a_process_substitution_imu_is_read(tmp_path, imu_csv):
    out = tmp_path / "out"
    proc = subprocess.run(["bash", "-c", f"{sys.executable} -m uareme_fusion run {imu_csv / 'rgb'} --imu "
                           f"<(cat {imu_csv / 'imu0' / 'data.csv'}) --normals {imu_csv / 'normals'} --out {out}"
                           f" {NO_FOCAL_SEARCH}"],
                          capture_output=True, text=True, env=subprocess_env(), timeout=120)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["source_info"]["has_imu"] and summary["imu_samples"] > 100 and summary["estimates"] == 20


def test_a_fifo_imu_with_a_writer_is_read_and_a_fifo_source_is_named(tmp_path, imu_csv):
    fifo = tmp_path / "imu.fifo"
    os.mkfifo(fifo)
    data = (imu_csv / "imu0" / "data.csv").read_bytes()
    writer = threading.Thread(target=lambda: fifo.write_bytes(data), daemon=True)
    writer.start()
    proc = cli("run", imu_csv / "rgb", "--imu", fifo, "--normals", imu_csv / "normals", "--out", tmp_path / "out",
               *NO_FOCAL_SEARCH.split())
    writer.join(timeout=10)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["imu_samples"] > 100
    proc = cli("run", fifo, "--out", tmp_path / "out2")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {fifo}: is a pipe (FIFO or process substitution), not a video, images or "
                                 "a dataset folder (a pipe is read only as an IMU CSV: --imu, or a name ending in .csv)"]


def test_a_fifo_nobody_writes_to_does_not_hang(tmp_path):
    fifo = tmp_path / "silent.fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match=r"silent.fifo: is a pipe \(FIFO\) and nothing was written to it within 0.2 s"):
        read_pipe_text(fifo, wait_s=0.2)


def test_a_symlink_loop_is_named(tmp_path):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    proc = cli("run", tmp_path / "loop", "--out", tmp_path / "o")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {tmp_path / 'loop'}: is a symbolic link loop, not a video, images or a "
                                 "dataset folder"]
    proc = cli("run", "sim:room", "--imu", tmp_path / "loop", "--out", tmp_path / "o")
    assert error_lines(proc) == [f"error: EuRoC IMU file {tmp_path / 'loop'} is a symbolic link loop"]


# ------------------------------------------------------------------------------ big photos
def test_big_photos_are_decoded_at_reduced_size(tmp_path):
    assert reduction_for((8000, 6000), ANALYSIS_MAX_PIXELS) == (4, cv2.IMREAD_REDUCED_COLOR_4)  # 48 MP -> 3 MP
    assert reduction_for((4000, 3000), ANALYSIS_MAX_PIXELS) == (2, cv2.IMREAD_REDUCED_COLOR_2)
    assert reduction_for((1920, 1080), ANALYSIS_MAX_PIXELS) == (1, None)
    assert reduction_for(None, ANALYSIS_MAX_PIXELS) == (1, None)
    image = np.zeros((2100, 2400, 3), np.uint8)
    image[:, :1200] = (0, 0, 255)  # red on the left in BGR
    cv2.imwrite(str(tmp_path / "big.png"), image)
    rgb = read_rgb(tmp_path / "big.png", ANALYSIS_MAX_PIXELS)
    assert rgb.shape == (1050, 1200, 3) and tuple(rgb[10, 10]) == (255, 0, 0) and tuple(rgb[10, -10]) == (0, 0, 0)
    assert read_rgb(tmp_path / "big.png").shape == (2100, 2400, 3)  # no limit: full size
