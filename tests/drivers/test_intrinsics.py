"""Camera intrinsics: `--intrinsics` values and camera files, the published values of TUM RGB-D and
ICL-NUIM recognised from folder names, undistortion, and `eval --normals depth` on a TUM-named folder
(a simulated sequence laid out as TUM publishes it: no scene.json, so K must come from the name)."""

from __future__ import annotations

import json
import re
import shutil

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.drivers import open_source
from uareme_fusion.drivers.intrinsics import (
    PUBLISHED,
    CameraModel,
    Undistorter,
    parse_intrinsics,
    published_camera,
    read_camera_file,
)
from uareme_fusion.errors import InputError

runner = CliRunner()
FR3_HFOV_DEG = 2 * np.degrees(np.arctan(320 / 535.4))
"""The simulated camera is given freiburg3's horizontal field of view at 640x480."""


@pytest.fixture(scope="module")
def tum_fr3(tmp_path_factory):
    """A simulated room in plain TUM RGB-D layout under a freiburg3 name (rgb, depth, groundtruth)."""
    root = tmp_path_factory.mktemp("tum")
    sim = root / "sim"
    result = runner.invoke(app, ["simulate", "room", "--out", str(sim), "--frames", "10", "--size", "640x480",
                                 "--fov-deg", f"{FR3_HFOV_DEG:.3f}"])
    assert result.exit_code == 0, result.output
    folder = root / "rgbd_dataset_freiburg3_sim_room"
    folder.mkdir()
    for name in ("rgb", "depth"):
        shutil.copytree(sim / name, folder / name)
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt"):
        shutil.copy(sim / name, folder / name)
    return folder


def one_error_line(result) -> str:
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def test_option_numbers_and_distortion():
    camera = parse_intrinsics("525, 526, 319.5, 239.5")
    np.testing.assert_array_equal(camera.K, [[525, 0, 319.5], [0, 526, 239.5], [0, 0, 1]])
    assert not camera.distorted and camera.origin == "--intrinsics 525, 526, 319.5, 239.5"
    camera = parse_intrinsics("500,500,320,240,-0.28,0.07,0.0002,0.00002")
    np.testing.assert_allclose(camera.dist, [-0.28, 0.07, 0.0002, 0.00002]) and camera.model == "radtan"


OPENCV_YAML = """%YAML:1.0
---
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 520.9, 0., 325.1, 0., 521.0, 249.7, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0.2312, -0.7849, -0.0033, -0.0001, 0.9172 ]
"""
OPENCV_JSON = json.dumps({"camera_matrix": [[520.9, 0, 325.1], [0, 521.0, 249.7], [0, 0, 1]],
                          "dist_coeffs": [0.2312, -0.7849, -0.0033, -0.0001, 0.9172]})
KALIBR = """cam0:
  camera_model: pinhole
  intrinsics: [520.9, 521.0, 325.1, 249.7]
  distortion_model: radtan
  distortion_coeffs: [0.2312, -0.7849, -0.0033, -0.0001]
  resolution: [640, 480]
  rostopic: /cam0/image_raw
"""
EUROC_SENSOR = """%YAML:1.0
sensor_type: camera
T_BS:
  cols: 4
  rows: 4
  data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [520.9, 521.0, 325.1, 249.7]
distortion_model: radial-tangential
distortion_coefficients: [0.2312, -0.7849, -0.0033, -0.0001]
"""


@pytest.mark.parametrize("name, text, n_dist", [("cam.yaml", OPENCV_YAML, 5), ("cam.json", OPENCV_JSON, 5),
                                                ("camchain.yaml", KALIBR, 4), ("sensor.yaml", EUROC_SENSOR, 4)])
def test_camera_files_in_the_formats_users_have(tmp_path, name, text, n_dist):
    (tmp_path / name).write_text(text)
    camera = parse_intrinsics(str(tmp_path / name))
    np.testing.assert_allclose(camera.K, PUBLISHED["TUM RGB-D freiburg2"].K)
    assert len(camera.dist) == n_dist and camera.dist[0] == 0.2312 and camera.model == "radtan"
    assert camera.origin == f"camera file {tmp_path / name}"


BAD_FILES = [
    ("not_yaml.yaml", "camera_matrix: [1, 2\n", r"camera file .*not_yaml.yaml: not valid YAML"),
    ("no_key.yaml", "fx: 500\n", r"camera file .*no_key.yaml: found no camera_matrix \(OpenCV\), intrinsics"),
    ("short.yaml", "camera_matrix:\n  data: [500, 0, 320, 0, 500]\n",
     r"camera file .*short.yaml: key camera_matrix: expected 9 numbers, got 5"),
    ("text_matrix.json", '{"camera_matrix": "fx=500"}', r"text_matrix.json: key camera_matrix: expected numbers"),
    ("kalibr_model.yaml", KALIBR.replace("radtan", "fov"),
     r"kalibr_model.yaml: key cam0.distortion_model: distortion model 'fov' is not supported"),
    ("kalibr_no_intrinsics.yaml", "cam0:\n  camera_model: pinhole\n",
     r"kalibr_no_intrinsics.yaml: key cam0.intrinsics is missing"),
    ("sensor_three.yaml", EUROC_SENSOR.replace("[520.9, 521.0, 325.1, 249.7]", "[520.9, 521.0, 325.1]"),
     r"sensor_three.yaml: key intrinsics: expected 4 numbers, got 3"),
    ("outside.yaml", KALIBR.replace("325.1, 249.7", "925.1, 249.7"),
     r"outside.yaml: principal point \(cx, cy\) = \(925.1, 249.7\) lies outside the 640x480 image"),
]


@pytest.mark.slow
@pytest.mark.parametrize("name, text, message", BAD_FILES, ids=[c[0] for c in BAD_FILES])
def test_bad_camera_files_name_the_file_and_key_on_the_command_line(tmp_path, tum_fr3, name, text, message):
    (tmp_path / name).write_text(text)
    result = runner.invoke(app, ["run", str(tum_fr3), "--intrinsics", str(tmp_path / name), "--out",
                                 str(tmp_path / "out")])
    assert re.search(message, one_error_line(result))


BAD_VALUES = [
    ("525,525,319.5", r"--intrinsics '525,525,319.5': expected 4 numbers fx,fy,cx,cy"),
    ("fx=525", r"--intrinsics 'fx=525': expected fx,fy,cx,cy \(pixels\) or a camera file, and no such file exists"),
    ("525,0,319.5,239.5", r"--intrinsics 525,0,319.5,239.5: focal lengths must be > 0 pixels, got fx = 525, fy = 0"),
    ("-525,525,319.5,239.5", r"focal lengths must be > 0 pixels, got fx = -525"),
    ("525,525,nan,239.5", r"--intrinsics 525,525,nan,239.5: intrinsics must be finite numbers"),
    ("525,525,700,239.5", r"--intrinsics 525,525,700,239.5: principal point \(cx, cy\) = \(700, 239.5\) lies "
                          r"outside the 640x480 image"),
    ("525,525,319.5,239.5,0.1", r"optionally followed by 4, 5 or 8 distortion coefficients .* got 5"),
]


@pytest.mark.parametrize("value, message", BAD_VALUES, ids=[c[0] for c in BAD_VALUES])
def test_bad_intrinsics_values_name_the_option_and_value(tmp_path, tum_fr3, value, message):
    result = runner.invoke(app, ["eval", str(tum_fr3), "--normals", "depth", "--intrinsics", value, "--out",
                                 str(tmp_path / "out")])
    assert re.search(message, one_error_line(result))


@pytest.mark.parametrize("command", ["image", "normals", "horizon", "ground"])
def test_every_image_command_takes_intrinsics(tmp_path, command):
    image = tmp_path / "a.png"
    cv2.imwrite(str(image), np.full((48, 64, 3), 90, np.uint8))
    out = tmp_path / {"horizon": "o.mp4", "image": "o.png"}.get(command, "o")
    result = runner.invoke(app, [command, str(image), "--out", str(out), "--intrinsics", "50,50,99,20"])
    assert result.exit_code == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error")]  # normals: progress first
    assert len(errors) == 1 and re.search(r"--intrinsics 50,50,99,20: principal point \(cx, cy\) = \(99, 20\) lies "
                                          "outside the 64x48 image", errors[0]), result.stderr


@pytest.mark.parametrize("folder, key", [("rgbd_dataset_freiburg1_desk", "TUM RGB-D freiburg1"),
                                         ("rgbd_dataset_freiburg2_xyz", "TUM RGB-D freiburg2"),
                                         ("rgbd_dataset_freiburg3_long_office_household", "TUM RGB-D freiburg3"),
                                         ("living_room_traj2_frei_png", "ICL-NUIM"), ("of_kt3", "ICL-NUIM")])
def test_published_intrinsics_from_folder_names(tmp_path, folder, key):
    camera = published_camera(tmp_path / folder)
    np.testing.assert_array_equal(camera.K, PUBLISHED[key].K)
    assert key in camera.origin and folder in camera.origin
    assert published_camera(tmp_path / "my_sequence") is None


def test_published_values():
    fr1, fr2, fr3 = (PUBLISHED[f"TUM RGB-D freiburg{i}"] for i in (1, 2, 3))
    np.testing.assert_array_equal([fr1.K[0, 0], fr1.K[1, 1], fr1.K[0, 2], fr1.K[1, 2]], [517.3, 516.5, 318.6, 255.3])
    np.testing.assert_array_equal([fr2.K[0, 0], fr2.K[1, 1], fr2.K[0, 2], fr2.K[1, 2]], [520.9, 521.0, 325.1, 249.7])
    np.testing.assert_array_equal([fr3.K[0, 0], fr3.K[1, 1], fr3.K[0, 2], fr3.K[1, 2]], [535.4, 539.2, 320.1, 247.6])
    assert fr1.distorted and fr2.distorted and not fr3.distorted


def test_eval_depth_normals_on_a_tum_named_folder(tmp_path, tum_fr3):
    result = runner.invoke(app, ["eval", str(tum_fr3), "--normals", "depth", "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["source_info"]["intrinsics_from"] == ("published TUM RGB-D freiburg3 intrinsics (folder name "
                                                         "rgbd_dataset_freiburg3_sim_room)")
    assert summary["frames_without_visual"] == 0 and summary["frames_without_depth"] == 0
    assert summary["are_deg"]["max"] < 1.5 and summary["tilt_deg"]["max"] < 1.0


def test_a_plain_tum_folder_needs_intrinsics_for_depth_normals(tmp_path, tum_fr3):
    folder = tmp_path / "my_room"
    shutil.copytree(tum_fr3, folder)
    result = runner.invoke(app, ["eval", str(folder), "--normals", "depth", "--out", str(tmp_path / "a")])
    assert re.search(r"my_room: --normals depth needs the camera intrinsics, and this source does not know them: "
                     r"give --intrinsics fx,fy,cx,cy or a camera file", one_error_line(result))
    result = runner.invoke(app, ["eval", str(folder), "--normals", "depth", "--intrinsics", "535.4,539.2,320.1,247.6",
                                 "--out", str(tmp_path / "b")])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["source_info"]["intrinsics_from"] == "--intrinsics 535.4,539.2,320.1,247.6"
    assert summary["are_deg"]["max"] < 1.5


def test_frames_without_depth_use_the_other_cues_and_are_counted(tmp_path, tum_fr3):
    folder = tmp_path / tum_fr3.name
    shutil.copytree(tum_fr3, folder)
    lines = (folder / "depth.txt").read_text().splitlines(keepends=True)
    data = [i for i, line in enumerate(lines) if not line.startswith("#")]
    (folder / "depth.txt").write_text("".join(line for i, line in enumerate(lines) if i not in data[3:6]))
    result = runner.invoke(app, ["eval", str(folder), "--normals", "depth", "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["frames"] == 10 and summary["frames_without_depth"] == 3
    assert summary["status_counts"]["DEPTH_MISSING"] == 3
    assert "3 rgb images have no depth image within 0.02 s (yielded without depth)" in summary["notes"][0]
    assert "note: " in result.stderr and "3 rgb images have no depth image" in result.stderr
    assert summary["are_deg"]["max"] < 3.0  # those 3 frames fall back to the line cue (2.6 deg here) and the IMU


def test_freiburg1_frames_are_undistorted_with_the_published_distortion(tmp_path, tum_fr3):
    folder = tmp_path / "rgbd_dataset_freiburg1_desk"
    shutil.copytree(tum_fr3, folder)
    with open_source(str(folder)) as src:
        assert "published TUM RGB-D freiburg1 intrinsics" in src.info.K_origin
        frame = src.read_frame(0)
        raw = src.seq.read_frame(0)
    np.testing.assert_array_equal(frame.K, PUBLISHED["TUM RGB-D freiburg1"].K)
    expected = Undistorter(PUBLISHED["TUM RGB-D freiburg1"], (480, 640))
    np.testing.assert_array_equal(frame.rgb, expected.image(raw.rgb))
    np.testing.assert_array_equal(frame.depth, expected.image(raw.depth, nearest=True))
    assert np.isin(frame.depth, np.r_[0.0, raw.depth.ravel()]).all()  # nearest: no blended depths
    assert not np.array_equal(frame.rgb, raw.rgb)


def test_intrinsics_option_replaces_the_source_k_and_says_so(tmp_path, tum_fr3):
    (tmp_path / "sensor.yaml").write_text(EUROC_SENSOR.replace("[752, 480]", "[640, 480]"))
    with open_source(str(tum_fr3), intrinsics=str(tmp_path / "sensor.yaml")) as src:
        assert src.info.K_origin == f"camera file {tmp_path / 'sensor.yaml'}"
        assert any("replaces the source's own K (published TUM RGB-D freiburg3" in n for n in src.report()[0])
        frame = next(e for e in src.events() if hasattr(e, "rgb"))
    np.testing.assert_array_equal(frame.K, PUBLISHED["TUM RGB-D freiburg2"].K)


def test_intrinsics_need_frames(tmp_path):
    (tmp_path / "imu.csv").write_text("#t,wx,wy,wz,ax,ay,az\n" + "".join(
        f"{1_000_000_000 + 5_000_000 * i},0,0,0,0,0,9.81\n" for i in range(10)))
    with pytest.raises(InputError, match="--intrinsics 500,500,320,240: intrinsics apply to camera frames, and "
                                         ".*imu.csv has none"):
        open_source(str(tmp_path / "imu.csv"), intrinsics="500,500,320,240")


def test_undistortion_puts_each_pixel_where_the_pinhole_model_sees_it():
    """A pattern f(x, y) drawn through radtan distortion comes back as f on the undistorted pixels."""
    camera = CameraModel(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.array([-0.28, 0.07, 0.0003, 0.0001]))
    h, w = 480, 640
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    distorted_px = np.column_stack([u.ravel(), v.ravel()])[:, None, :]
    ideal = cv2.undistortPoints(distorted_px, camera.K, camera.dist, P=camera.K).reshape(h, w, 2)

    def pattern(x, y):
        return 127.5 + 100 * np.sin(x / 23.0) * np.cos(y / 17.0)

    image = np.clip(np.rint(pattern(ideal[..., 0], ideal[..., 1])), 0, 255).astype(np.uint8)
    restored = Undistorter(camera, (h, w)).image(image).astype(float)
    inner = (slice(60, h - 60), slice(80, w - 80))
    error = np.abs(restored - pattern(u, v))[inner]
    assert np.median(error) < 1.5 and np.percentile(error, 99) < 6.0
    assert np.median(np.abs(image.astype(float) - pattern(u, v))[inner]) > 5  # distortion is not small


def test_camera_file_for_euroc_is_read_with_the_same_reader(tmp_path):
    (tmp_path / "sensor.yaml").write_text(EUROC_SENSOR)
    camera = read_camera_file(tmp_path / "sensor.yaml")
    assert camera.image_size == (480, 752) and camera.model == "radtan"
