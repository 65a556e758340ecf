"""The pipeline commands (run, eval, horizon, ground, image) under bad input: one red line on stderr
naming the problem, no traceback; exit 2 for a user mistake, 1 when a source fails mid-stream (the
outputs written so far kept), 130 for Ctrl-C. Readers, configs and the other commands are covered by
the phase-1 files (test_bad_input_*.py); these cases go through the pipeline's command line."""

from __future__ import annotations

import csv
import json
import re

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from helpers import png_bytes  # pytest puts tests/ on sys.path

runner = CliRunner()
N_FRAMES = 5
IMU_HEADER = "#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n"


def imu_rows(n: int = 40, rate_hz: float = 200.0) -> str:
    return "".join(f"{int(k * 1e9 / rate_hz)},0.01,0.02,0.0,0.0,0.0,9.81\n" for k in range(n))


def write_video(path, n: int = N_FRAMES, size=(64, 48)) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, size)
    rng = np.random.default_rng(0)
    for _ in range(n):
        writer.write(rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8))
    writer.release()


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Inputs shared by the cases: a simulated dataset, a video, images, normal maps, broken files."""
    w = tmp_path_factory.mktemp("inputs")
    result = runner.invoke(app, ["simulate", "room", "--frames", "4", "--size", "64x48", "--out", str(w / "sim4")])
    assert result.exit_code == 0, result.output
    write_video(w / "clip.avi")
    (w / "normals").mkdir()
    rng = np.random.default_rng(1)
    for i in range(8):
        nm = manhattan_normal_map(np.eye(3), rng, height=12, width=16, noise_deg=3.0)
        np.savez(w / "normals" / f"{i:06d}.npz", normals=nm.normals, kappa=nm.kappa)
    (w / "images").mkdir()
    for i in range(3):
        cv2.imwrite(str(w / "images" / f"{i}.png"), np.full((48, 64, 3), 40 * i, np.uint8))
    (w / "empty").mkdir()
    (w / "no_normals").mkdir()
    (w / "no_normals" / "readme.txt").write_text("x")
    for sub in ("rgb", "depth"):
        (w / "rgbd_no_index" / sub).mkdir(parents=True)
    (w / "rgb_only" / "rgb").mkdir(parents=True)
    (w / "euroc_empty" / "mav0").mkdir(parents=True)
    (w / "file.txt").write_text("a file, not a folder\n")
    (w / "text.mp4").write_text("not a video\n")
    (w / "zero.avi").write_bytes(b"")
    (w / "garbage.hdf5").write_bytes(b"not an hdf5 file")
    (w / "text.png").write_text("not an image\n")
    (w / "zero.png").write_bytes(b"")
    (w / "huge.png").write_bytes(png_bytes(40_000, 40_000))
    (w / "model.pt").write_bytes(b"not a torchscript archive")
    (w / "imu_good.csv").write_text(IMU_HEADER + imu_rows())
    (w / "imu_six_columns.csv").write_text(IMU_HEADER + "0,0,0,0,0,9.81\n")
    (w / "imu_text.csv").write_text(IMU_HEADER + "0,0,0,x,0,0,9.81\n")
    (w / "imu_header_only.csv").write_text(IMU_HEADER)
    (w / "imu_nan.csv").write_text(IMU_HEADER + "0,nan,0,0,0,0,9.81\n" + imu_rows(5))
    (w / "imu_semicolons.csv").write_text(IMU_HEADER + "0;0;0;0;0;0;9.81\n")
    (w / "imu_empty.csv").write_bytes(b"")
    (w / "two_normals").mkdir()
    for i in range(2):
        (w / "two_normals" / f"{i:06d}.npz").write_bytes((w / "normals" / f"{i:06d}.npz").read_bytes())
    (w / "images_one_bad").mkdir()
    for i in range(4):
        cv2.imwrite(str(w / "images_one_bad" / f"{i}.png"), np.full((48, 64, 3), 50, np.uint8))
    (w / "images_one_bad" / "2.png").write_bytes(png_bytes(64, 48))  # header fine, pixel data cut short
    return w


def assert_error(result, code: int, message: str, alone: bool | None = None) -> str:
    """Exit status `code`, exactly one `error:` line on stderr matching `message`, no traceback; with
    `alone` (default: for exit 2) the error is the only line on stderr (nothing ran before it)."""
    assert result.exit_code == code, (result.exit_code, result.output, result.exception)
    errors = [line for line in result.stderr.splitlines() if line.startswith("error")]
    assert len(errors) == 1, result.stderr
    assert "Traceback" not in result.output, result.output
    assert re.search(message, errors[0]), errors[0]
    if (code == 2) if alone is None else alone:  # a mistake found before any frame: the only line
        assert result.stderr.strip().splitlines() == errors, result.stderr
    return errors[0]


def invoke(world, tmp_path, args: list[str], files: dict | None = None):
    """Run the command line with W -> the shared inputs and T -> this case's own folder."""
    for name, text in (files or {}).items():
        (tmp_path / name).write_text(text)
    subst = [a.replace("W/", f"{world}/").replace("T/", f"{tmp_path}/") for a in args]
    return runner.invoke(app, subst)


SOURCE_CASES = [
    ("missing_path", ["W/nope.mp4"], "nope.mp4: no such file or folder"),
    ("empty_folder", ["W/empty"], r"folder .*empty: not a dataset .* holds no image files"),
    ("rgb_and_depth_without_index", ["W/rgbd_no_index"], "has depth/ and rgb/ but no index file"),
    ("rgb_without_index", ["W/rgb_only"], "has rgb/ but no index file: expected rgb.txt"),
    ("euroc_without_data", ["W/euroc_empty"], "EuRoC folder .*found no cam0/data.csv or imu0/data.csv"),
    ("text_named_mp4", ["W/text.mp4"], r"text.mp4: neither a video \(it holds text\) nor an IMU table \(is not an "
                                       r"EuRoC IMU file: line 1 has 3 column"),
    ("zero_byte_video", ["W/zero.avi"], r"zero.avi: empty file \(0 bytes\), expected a video, an image or an IMU table"),
    ("text_named_png", ["W/text.png"], "text.png"),
    ("zero_byte_png", ["W/zero.png"], "zero.png"),
    ("unknown_scenario", ["sim:moon"], "unknown scenario; valid: room, office"),
    ("glob_matches_nothing", ["W/empty/*.png"], r"image pattern .*matches no files"),
    ("broad_not_hdf5", ["W/garbage.hdf5"], "Cannot read BROAD file .*garbage.hdf5"),
    ("imu_source_six_columns", ["W/imu_six_columns.csv"], "not an EuRoC IMU file: line 2 has 6 column"),
    ("imu_source_header_only", ["W/imu_header_only.csv"], "holds no IMU samples"),
    ("imu_source_empty_file", ["W/imu_empty.csv"], "imu_empty.csv"),
    ("oak_without_depthai", ["oak"], r"install uareme-fusion\[oak\]"),
    ("fps_on_a_dataset", ["W/sim4", "--fps", "10"], "--fps does not apply"),
    ("fps_zero", ["W/clip.avi", "--fps", "0"], "--fps must be > 0, got 0"),
    ("fps_negative", ["W/images", "--fps", "-5"], "--fps must be > 0, got -5"),
    ("fps_nan", ["W/clip.avi", "--fps", "nan"], "--fps must be > 0, got nan"),
    ("fps_text", ["W/clip.avi", "--fps", "fast"], "Invalid value for '--fps'"),
]

IMU_CASES = [
    ("imu_missing", ["W/clip.avi", "--imu", "W/nope.csv"], "nope.csv"),
    ("imu_six_columns", ["W/clip.avi", "--imu", "W/imu_six_columns.csv"], "line 2 has 6 column"),
    ("imu_text_value", ["W/clip.avi", "--imu", "W/imu_text.csv"], r"imu_text.csv: line 2, column 4"),
    ("imu_header_only", ["W/clip.avi", "--imu", "W/imu_header_only.csv"], "holds no IMU samples"),
    ("imu_nan_value", ["W/clip.avi", "--imu", "W/imu_nan.csv"], "NaN or infinite"),
    ("imu_semicolons", ["W/clip.avi", "--imu", "W/imu_semicolons.csv"], "imu_semicolons.csv"),
    ("imu_is_a_folder", ["W/clip.avi", "--imu", "W/empty"], r"empty: is a folder, and an IMU file inside it \(data.csv"),
    ("imu_on_a_source_with_imu", ["W/sim4", "--imu", "W/imu_good.csv"], "already has an IMU; cannot merge"),
]

CONFIG_CASES = [
    ("config_missing", ["--config", "T/none.yaml"], {}, "none.yaml"),
    ("config_unknown_key", ["--config", "T/c.yaml"], {"c.yaml": "backend: mekf\nbakend: single\n"}, "bakend"),
    ("config_backend_wrong_type", ["--config", "T/c.yaml"], {"c.yaml": "backend: 3\n"}, "backend"),
    ("config_backend_unknown", ["--config", "T/c.yaml"], {"c.yaml": "backend: kalman\n"}, "backend"),
    ("config_kappa_cap_negative", ["--config", "T/c.yaml"], {"c.yaml": "kappa_cap: -1\n"}, "kappa_cap"),
    ("config_kappa_cap_text", ["--config", "T/c.yaml"], {"c.yaml": "kappa_cap: lots\n"}, "kappa_cap"),
    ("config_max_frames_zero", ["--config", "T/c.yaml"], {"c.yaml": "max_frames: 0\n"}, "max_frames"),
    ("config_fov_too_wide", ["--config", "T/c.yaml"], {"c.yaml": "assumed_fov_deg: 200\n"}, "assumed_fov_deg"),
    ("config_threshold_negative", ["--config", "T/c.yaml"], {"c.yaml": "ground_threshold_deg: -3\n"},
     "ground_threshold_deg"),
    ("config_normals_list", ["--config", "T/c.yaml"], {"c.yaml": "normals: [1, 2]\n"}, "normals"),
    ("config_mekf_not_a_mapping", ["--config", "T/c.yaml"], {"c.yaml": "mekf: 5\n"}, "mekf"),
    ("config_mekf_unknown_key", ["--config", "T/c.yaml"], {"c.yaml": "mekf:\n  gyro_nose: 1\n"}, "gyro_nose"),
    ("config_mekf_wrong_type", ["--config", "T/c.yaml"], {"c.yaml": "mekf:\n  imu_gap_limit_s: soon\n"},
     "imu_gap_limit_s"),
    ("config_mekf_negative_noise", ["--config", "T/c.yaml"],
     {"c.yaml": "mekf:\n  gyro_noise_rad_s_sqrt_hz: -1\n"}, "gyro_noise_rad_s_sqrt_hz"),
    ("config_preset_unknown", ["--config", "T/c.yaml"], {"c.yaml": "mekf_preset: rocket\n"}, "rocket"),
    ("config_smoother_unknown_key", ["--config", "T/c.yaml"],
     {"c.yaml": "backend: smoother\nsmoother:\n  windw: 3\n"}, "windw"),
    ("config_a_list", ["--config", "T/c.yaml"], {"c.yaml": "- backend\n- mekf\n"}, "c.yaml"),
    ("config_is_a_folder", ["--config", "W/empty"], {}, "empty"),
]

OPTION_CASES = [
    ("backend_unknown", ["W/sim4", "--backend", "kalman"], "backend"),
    ("normals_unknown", ["W/sim4", "--normals", "magic"], "--normals 'magic': expected auto, learned, depth"),
    ("normals_depth_without_depth", ["W/clip.avi", "--normals", "depth"], "--normals depth needs a depth map"),
    ("normals_model_missing", ["W/clip.avi", "--normals", "W/nope.pt"], "nope.pt: model file not found"),
    ("normals_model_corrupt", ["W/clip.avi", "--normals", "W/model.pt"], "model.pt"),
    ("normals_folder_without_maps", ["W/clip.avi", "--normals", "W/no_normals"], "no normal maps"),
    ("cues_unknown", ["W/sim4", "--cues", "normals,edges"],
     r"--cues 'normals,edges': expected a comma-separated selection of normals, lines"),
    ("cues_empty", ["W/sim4", "--cues", ","], "expected a comma-separated selection of normals, lines"),
    ("preset_unknown", ["W/sim4", "--preset", "rocket"], "rocket"),
    ("preset_missing_yaml", ["W/sim4", "--preset", "W/nope.yaml"], "nope.yaml"),
    ("max_frames_zero", ["W/sim4", "--max-frames", "0"], "max_frames"),
    ("max_frames_negative", ["W/sim4", "--max-frames", "-2"], "max_frames"),
    ("max_frames_text", ["W/sim4", "--max-frames", "all"], "Invalid value for '--max-frames'"),
    ("unknown_option", ["W/sim4", "--bogus"], r"No such option: --bogus"),
    ("missing_source", [], "Missing argument 'source'"),
]


def out_args(tmp_path):
    return ["--out", str(tmp_path / "out")]


@pytest.mark.parametrize("case, args, message", SOURCE_CASES, ids=[c[0] for c in SOURCE_CASES])
def test_run_bad_sources(world, tmp_path, case, args, message):
    assert_error(invoke(world, tmp_path, ["run", *args, *out_args(tmp_path)]), 2, message)


@pytest.mark.parametrize("case, args, message", IMU_CASES, ids=[c[0] for c in IMU_CASES])
def test_run_bad_imu_files(world, tmp_path, case, args, message):
    assert_error(invoke(world, tmp_path, ["run", *args, *out_args(tmp_path)]), 2, message)


@pytest.mark.parametrize("case, args, files, message", CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_run_bad_config_files(world, tmp_path, case, args, files, message):
    result = invoke(world, tmp_path, ["run", "W/sim4", *args, *out_args(tmp_path)], files)
    assert_error(result, 2, message)


@pytest.mark.parametrize("case, args, message", OPTION_CASES, ids=[c[0] for c in OPTION_CASES])
def test_run_bad_options(world, tmp_path, case, args, message):
    assert_error(invoke(world, tmp_path, ["run", *args, *out_args(tmp_path)]), 2, message)


EVAL_CASES = [
    ("video", ["W/clip.avi", "--normals", "W/normals"], "clip.avi: this source has no ground truth to evaluate"),
    ("image_folder", ["W/images", "--normals", "W/normals"], "images: this source has no ground truth"),
    ("imu_csv", ["W/imu_good.csv"], "imu_good.csv: this source has no ground truth"),
    ("video_with_imu", ["W/clip.avi", "--imu", "W/imu_good.csv", "--normals", "W/normals"], "no ground truth"),
    ("missing_out", ["W/sim4", "NO_OUT"], "Missing option '--out'"),
    ("missing_source", ["NO_SOURCE"], "Missing argument 'source'"),
]


@pytest.mark.parametrize("case, args, message", EVAL_CASES, ids=[c[0] for c in EVAL_CASES])
def test_eval_without_ground_truth_or_arguments(world, tmp_path, case, args, message):
    out = [] if "NO_OUT" in args else out_args(tmp_path)
    result = invoke(world, tmp_path, ["eval", *[a for a in args if not a.startswith("NO_")], *out])
    assert_error(result, 2, message)
    assert not (tmp_path / "out" / "trajectory.tum").exists()  # refused before running


OUTPUT_CASES = [
    ("run_out_is_a_file", ["run", "W/sim4", "--out", "W/file.txt"], "file.txt: exists and is not a folder"),
    ("run_out_under_a_file", ["run", "W/sim4", "--out", "W/file.txt/sub"], "cannot create the output folder"),
    ("eval_out_is_a_file", ["eval", "W/sim4", "--out", "W/file.txt"], "exists and is not a folder"),
    ("ground_out_is_a_file", ["ground", "W/sim4", "--out", "W/file.txt"], "exists and is not a folder"),
    ("horizon_out_not_a_video", ["horizon", "W/sim4", "--out", "T/overlay.txt"],
     r"--out .*overlay.txt: unsupported video extension; use one of .mp4"),
    ("horizon_out_without_extension", ["horizon", "W/sim4", "--out", "T/overlay"], "unsupported video extension"),
    ("horizon_out_under_a_file", ["horizon", "W/sim4", "--out", "W/file.txt/o.mp4"], "cannot create the output"),
    ("record_into_a_file", ["run", "W/sim4", "--out", "T/out", "--record", "W/file.txt"], "file.txt"),
]


@pytest.mark.parametrize("case, args, message", OUTPUT_CASES, ids=[c[0] for c in OUTPUT_CASES])
def test_output_paths_that_cannot_be_written(world, tmp_path, case, args, message):
    assert_error(invoke(world, tmp_path, args), 2, message)


OVERLAY_CASES = [
    ("horizon_fov_zero", ["horizon", "--fov-deg", "0"], r"assumed_fov_deg: Input should be greater than 1 \(got 0"),
    ("horizon_fov_180", ["horizon", "--fov-deg", "180"], "assumed_fov_deg: Input should be less than 179"),
    ("horizon_fov_negative", ["horizon", "--fov-deg", "-60"], "assumed_fov_deg"),
    ("horizon_fov_nan", ["horizon", "--fov-deg", "nan"], "assumed_fov_deg"),
    ("horizon_fov_text", ["horizon", "--fov-deg", "wide"], "Invalid value for '--fov-deg'"),
    ("horizon_imu_only_source", ["horizon", "SRC=W/imu_good.csv"], "'horizon' draws on images, and this source has none"),
    ("horizon_backend_unknown", ["horizon", "--backend", "ukf"], "backend"),
    ("ground_threshold_zero", ["ground", "--threshold-deg", "0"], "ground_threshold_deg: Input should be greater than 0"),
    ("ground_threshold_90", ["ground", "--threshold-deg", "90"], "ground_threshold_deg: Input should be less than 90"),
    ("ground_threshold_nan", ["ground", "--threshold-deg", "nan"], "ground_threshold_deg"),
    ("ground_threshold_text", ["ground", "--threshold-deg", "flat"], "Invalid value for '--threshold-deg'"),
    ("ground_imu_only_source", ["ground", "SRC=W/imu_good.csv"], "'ground' draws on images, and this source has none"),
    ("ground_normals_depth_on_video", ["ground", "SRC=W/clip.avi", "--normals", "depth"], "needs a depth map"),
    ("ground_missing_source", ["ground", "SRC=W/nope"], "nope: no such file or folder"),
]


@pytest.mark.parametrize("case, args, message", OVERLAY_CASES, ids=[c[0] for c in OVERLAY_CASES])
def test_horizon_and_ground_bad_options(world, tmp_path, case, args, message):
    command, rest = args[0], args[1:]
    source = next((a[4:] for a in rest if a.startswith("SRC=")), "W/sim4")
    rest = [a for a in rest if not a.startswith("SRC=")]
    out = ["--out", str(tmp_path / ("o.mp4" if command == "horizon" else "out"))]
    assert_error(invoke(world, tmp_path, [command, source, *rest, *out]), 2, message)
    assert not (tmp_path / "o.mp4").exists()


IMAGE_CASES = [
    ("missing_file", ["W/nope.png"], "nope.png"),
    ("folder_without_images", ["W/no_normals"], "no_normals: no images"),
    ("zero_bytes", ["W/zero.png"], "zero.png: empty file"),
    ("text_file", ["W/text.png"], "text.png: not a readable image"),
    ("huge_header", ["W/huge.png"], "40000 x 40000 pixels"),
    ("normals_unknown", ["W/images/1.png", "--normals", "magic"], "--normals 'magic': expected auto"),
    ("normals_model_missing", ["W/images/1.png", "--normals", "W/nope.pt"], "nope.pt: model file not found"),
    ("normals_depth", ["W/images/1.png", "--normals", "depth"], "--normals depth needs a depth map"),
    ("normals_source", ["W/images/1.png", "--normals", "source"], "frame 0 carries no normals"),
    ("normals_empty_folder", ["W/images/1.png", "--normals", "W/no_normals"], "no normal maps"),
    ("blank_image", ["W/images/0.png", "--normals", "W/two_normals", "ZERO_KAPPA"], "no confident normals"),
    ("out_not_an_image", ["W/images/1.png", "--normals", "W/normals", "--out", "T/o.txt"],
     "o.txt: the overlay is an image; use a .png or .jpg name"),
    ("out_under_a_file", ["W/images/1.png", "--normals", "W/normals", "--out", "W/file.txt/o.png"],
     "file.txt: exists and is not a folder"),
    ("fov_zero", ["W/images/1.png", "--normals", "W/normals", "--fov-deg", "0"],
     "--fov-deg must be between 1 and 179 degrees, got 0"),
    ("fov_nan", ["W/images/1.png", "--normals", "W/normals", "--fov-deg", "nan"], "--fov-deg must be between"),
    ("fov_text", ["W/images/1.png", "--fov-deg", "wide"], "Invalid value for '--fov-deg'"),
    ("json_takes_no_value", ["W/images/1.png", "--json=yes"], "--json"),
    ("missing_argument", [], "Missing argument 'image'"),
]


@pytest.mark.parametrize("case, args, message", IMAGE_CASES, ids=[c[0] for c in IMAGE_CASES])
def test_image_bad_input(world, tmp_path, case, args, message):
    if "ZERO_KAPPA" in args:  # a map with no confident pixel
        folder = tmp_path / "zero_kappa"
        folder.mkdir()
        data = dict(np.load(world / "normals" / "000000.npz"))
        np.savez(folder / "000000.npz", normals=data["normals"], kappa=np.zeros_like(data["kappa"]))
        args = [str(folder) if a == "W/two_normals" else a for a in args if a != "ZERO_KAPPA"]
    result = invoke(world, tmp_path, ["image", *args])
    assert_error(result, 2, message)
    assert result.stdout == "" and not (tmp_path / "o.txt").exists()


MID_STREAM_CASES = [
    ("image_that_stops_decoding", ["W/huge.png"], 1, r"huge.png.*outputs so far kept in", 0),
    ("bad_image_in_a_folder", ["W/images_one_bad", "--normals", "W/normals"], 1, r"2.png", 2),
    ("fewer_normal_maps_than_frames", ["W/clip.avi", "--normals", "W/two_normals"], 2,
     r"2 normal maps but the source has a frame 2 \(outputs so far kept in", 2),
]


@pytest.mark.parametrize("case, args, code, message, frames", MID_STREAM_CASES, ids=[c[0] for c in MID_STREAM_CASES])
def test_mid_stream_failures_keep_the_outputs(world, tmp_path, case, args, code, message, frames):
    """The frames before the failure are in trajectory.tum and estimates.csv; summary.json says why it
    stopped; the exit status is 1 for a source failure, 2 for bad input met mid-stream."""
    result = invoke(world, tmp_path, ["run", *args, *out_args(tmp_path)])
    assert_error(result, code, message, alone=False)
    out = tmp_path / "out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] == ("source_error" if code == 1 else "input_error")
    assert summary["frames"] == frames and summary["error"] in result.stderr.replace("\n", "")
    lines = [line for line in (out / "trajectory.tum").read_text().splitlines() if not line.startswith("#")]
    assert len(lines) == frames and all(len(line.split()) == 8 for line in lines)
    with open(out / "estimates.csv") as fh:
        assert len(list(csv.DictReader(fh))) == frames


def test_unknown_scenario_message_keeps_its_name(world, tmp_path):
    assert_error(invoke(world, tmp_path, ["run", "sim:moon", *out_args(tmp_path)]), 2, "sim:moon: unknown scenario")


def test_config_yaml_syntax_error_is_one_line(world, tmp_path):
    result = invoke(world, tmp_path, ["run", "W/sim4", "--config", "T/c.yaml", *out_args(tmp_path)],
                    {"c.yaml": "backend: [mekf\n"})
    assert_error(result, 2, r"c.yaml is not valid YAML at line \d+, column \d+: expected")


BENCH_CASES = [
    ("soak_duration_zero", ["soak", "--duration-s", "0"], "Invalid value for '--duration-s'"),
    ("soak_noise_above_90", ["soak", "--normals-noise-deg", "120"], "Invalid value for '--normals-noise-deg'"),
    ("pipeline_duration_zero", ["pipeline", "--duration-s", "0"], "Invalid value for '--duration-s'"),
    ("pipeline_memory_negative", ["pipeline", "--memory-duration-s", "-1"], "Invalid value for '--memory-duration-s'"),
    ("horizon_without_data", ["horizon", "--data", "/nonexistent"], "--data /nonexistent: no eurasian_cities/ folder"),
]


@pytest.mark.parametrize("case, args, message", BENCH_CASES, ids=[c[0] for c in BENCH_CASES])
def test_bench_pipeline_and_soak_refuse_bad_options_before_running(case, args, message):
    result = runner.invoke(app, ["bench", *args])
    assert_error(result, 2, message)
    assert result.stdout == ""
