"""The command line under bad input: one red line on stderr naming the problem, no traceback, exit
status 2, for every command that exists (solve, simulate, compare, bench, demo) and for usage errors."""

from __future__ import annotations

import re
import subprocess
import sys

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from helpers import png_bytes  # pytest puts tests/ on sys.path

runner = CliRunner()
RNG = np.random.default_rng(3)
NORMAL_MAP = manhattan_normal_map(np.eye(3), RNG, height=12, width=16, noise_deg=5.0)


def assert_one_error_line(result, message: str) -> None:
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ") and "Traceback" not in result.output, result.stderr
    assert re.search(message, lines[0]), lines[0]


def make_file(path, kind):
    if kind == "folder":
        path.mkdir()
    elif kind == "zero":
        path.write_bytes(b"")
    elif kind == "text":
        path.write_text("not a map\n")
    elif kind == "huge_png":
        path.write_bytes(png_bytes(40_000, 40_000))
    elif kind == "gray_png":
        cv2.imwrite(str(path), np.zeros((8, 8), np.uint8))
    elif kind == "nan_map":
        np.save(path, np.full((6, 6, 3), np.nan, np.float32))
    elif kind == "npz_as_npy":
        with open(path, "wb") as fh:
            np.savez(fh, normals=NORMAL_MAP.normals)
    elif kind == "ints":
        np.save(path, np.ones((6, 6, 3), np.int8))
    elif kind == "good":
        np.save(path, NORMAL_MAP.normals)
    return path


SOLVE_CASES = [
    ("missing_file", "m.npy", None, [], "m.npy: no such file"),
    ("folder", "d.npy", "folder", [], "d.npy: is a folder"),
    ("zero_bytes_png", "z.png", "zero", [], "z.png: empty file"),
    ("text_png", "t.png", "text", [], "t.png: not a readable image"),
    ("huge_png", "h.png", "huge_png", [], "40000 x 40000 pixels"),
    ("grayscale_png", "g.png", "gray_png", [], "3 colour channels"),
    ("all_nan", "n.npy", "nan_map", [], r"No valid normals in a map of shape \(6, 6, 3\)"),
    ("npz_named_npy", "a.npy", "npz_as_npy", [], r"an \.npz archive"),
    ("integer_map", "i.npy", "ints", [], "floating-point normals"),
    ("unsupported_extension", "m.txt", "text", [], "unsupported normal map format '.txt'"),
    ("bad_frame", "ok.npy", "good", ["--frame", "ros"], "Unknown normal frame 'ros'"),
    ("unknown_option", "ok.npy", "good", ["--bogus"], r"No such option: --bogus \(see 'uareme-fusion solve --help'\)"),
    ("json_takes_no_value", "ok.npy", "good", ["--json=yes"], "--json"),
]


@pytest.mark.parametrize("case, name, kind, extra, message", SOLVE_CASES, ids=[c[0] for c in SOLVE_CASES])
def test_solve_bad_input(tmp_path, case, name, kind, extra, message):
    path = tmp_path / name
    if kind is not None:
        make_file(path, kind)
    result = runner.invoke(app, ["solve", str(path), *extra])
    assert_one_error_line(result, message)
    assert result.stdout == ""


def test_solve_missing_argument():
    assert_one_error_line(runner.invoke(app, ["solve"]), r"Missing argument 'file'")


SIMULATE_CASES = [
    ("unknown_scenario", ["moon"], "unknown scenario 'moon'; valid: room"),
    ("frames_not_a_number", ["room", "--frames", "ten"], "Invalid value for '--frames'"),
    ("zero_frames", ["room", "--frames", "0"], "--frames must be between 1 and 1000000, got 0"),
    ("negative_frames", ["room", "--frames", "-5"], "--frames must be between"),
    ("size_without_x", ["room", "--size", "320"], "--size must look like WIDTHxHEIGHT"),
    ("size_negative", ["room", "--size", "-320x240"], "--size must look like WIDTHxHEIGHT"),
    ("size_tiny", ["room", "--size", "4x4"], "--size must be at least 8x8"),
    ("size_huge", ["room", "--size", "100000x100000"], "at most 4096x4096"),
    ("fps_zero", ["room", "--fps", "0"], "--fps must be between 1 and 1000"),
    ("fps_nan", ["room", "--fps", "nan"], "--fps must be between"),
    ("imu_rate_low", ["room", "--imu-rate", "5"], "--imu-rate must be between 100 and 1000 Hz"),
    ("fov_wide", ["room", "--fov-deg", "150"], "--fov-deg must be between 45 and 95"),
    ("seed_negative", ["room", "--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    ("seed_text", ["room", "--seed", "abc"], "Invalid value for '--seed'"),
    ("out_missing", ["room", "--frames", "1", "NO_OUT"], "Missing option '--out'"),
]


@pytest.mark.parametrize("case, args, message", SIMULATE_CASES, ids=[c[0] for c in SIMULATE_CASES])
def test_simulate_bad_options(tmp_path, case, args, message):
    out = [] if "NO_OUT" in args else ["--out", str(tmp_path / "out")]
    result = runner.invoke(app, ["simulate", *[a for a in args if a != "NO_OUT"], *out])
    assert_one_error_line(result, message)
    assert not (tmp_path / "out").exists()  # nothing written


def test_simulate_refuses_a_file_or_a_non_empty_folder(tmp_path):
    (tmp_path / "file").write_text("x")
    result = runner.invoke(app, ["simulate", "room", "--frames", "1", "--out", str(tmp_path / "file")])
    assert_one_error_line(result, "exists and is not a folder")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "a.txt").write_text("x")
    result = runner.invoke(app, ["simulate", "room", "--frames", "1", "--out", str(tmp_path / "full")])
    assert_one_error_line(result, "is not empty; pass --force")


def dataset(root, n=3, rgb=None, imu=None, gt=None):
    """A minimal dataset folder for `compare`: normals/ with n small maps and rgb.txt."""
    (root / "normals").mkdir(parents=True)
    for i in range(n):
        np.savez(root / "normals" / f"{i:06d}.npz", normals=NORMAL_MAP.normals, kappa=NORMAL_MAP.kappa)
    (root / "rgb.txt").write_text(rgb if rgb is not None else "".join(f"{i / 10:.1f} rgb/{i}.png\n" for i in range(n)))
    if imu is not None:
        (root / "imu0").mkdir()
        (root / "imu0" / "data.csv").write_text(imu)
    if gt is not None:
        (root / "groundtruth.txt").write_text(gt)
    return root


COMPARE_DATASET_CASES = [
    ("rgb_list_text_time", {"rgb": "zero rgb/0.png\n0.1 rgb/1.png\n0.2 rgb/2.png\n"}, r"rgb.txt: line 1, column 1"),
    ("rgb_list_unsorted", {"rgb": "0.2 a\n0.1 b\n0.3 c\n"}, r"rgb.txt: line 2: timestamp 0.1 is not after"),
    ("rgb_list_too_short", {"rgb": "0.0 a\n0.1 b\n"}, "3 normal maps but 2 frame times"),
    ("imu_nan", {"imu": "#h\n0,nan,0,0,0,0,9.8\n"},
     r"data.csv: 1 row\(s\) hold a NaN or infinite gyro or accel value \(line 2\)"),
    ("imu_six_columns", {"imu": "#h\n0,0,0,0,0,9.8\n"}, "data.csv is not an EuRoC IMU file: line 2 has 6 column"),
    ("imu_text", {"imu": "#h\n0,0,0,0,0,x,9.8\n"}, r"data.csv: line 2, column 6"),
    ("imu_header_only", {"imu": "#h\n"}, "holds no IMU samples"),
    ("groundtruth_zero_quaternion", {"gt": "0 0 0 0 0 0 0 0\n1 0 0 0 0 0 0 1\n"}, "groundtruth.txt: 1 quaternion"),
    ("groundtruth_short", {"gt": "0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n"}, "ground truth covers"),
    ("groundtruth_seven_columns", {"gt": "0 0 0 0 0 0 1\n"}, "not a TUM trajectory file"),
]


@pytest.mark.parametrize("case, files, message", COMPARE_DATASET_CASES, ids=[c[0] for c in COMPARE_DATASET_CASES])
def test_compare_bad_dataset_files(tmp_path, case, files, message):
    root = dataset(tmp_path / "seq", **files)
    result = runner.invoke(app, ["compare", str(root), "--out", str(tmp_path / "out")])
    assert_one_error_line(result, message)


def test_compare_corrupt_normal_map_names_it(tmp_path):
    root = dataset(tmp_path / "seq")
    (root / "normals" / "000001.npz").write_bytes(b"PK\x03\x04 truncated")
    result = runner.invoke(app, ["compare", str(root), "--out", str(tmp_path / "out")])
    assert_one_error_line(result, r"000001.npz: not a readable normals file")


COMPARE_OPTION_CASES = [
    ("no_source", [], "give either a dataset folder SOURCE or --synthetic"),
    ("both_sources", ["SEQ", "--synthetic", "walk"], "not both"),
    ("missing_folder", ["MISSING"], "no such file or folder"),
    ("file_as_source", ["FILE"], "is not an EuRoC IMU file: line 1 has 1 column"),  # text, not a video: read as an IMU table
    ("empty_folder", ["EMPTY"], "not a dataset .* holds no image files"),
    ("unknown_trajectory", ["--synthetic", "moon"], "unknown trajectory 'moon'"),
    ("negative_duration", ["--synthetic", "static", "--duration-s", "-1"], "Invalid value for '--duration-s'"),
    ("huge_duration", ["--synthetic", "static", "--duration-s", "1e9"], "less than or equal to 3600"),
    ("negative_seed", ["--synthetic", "static", "--seed", "-3"], "Invalid value for '--seed'"),
    ("drop_fraction_above_one", ["--synthetic", "static", "--drop-fraction", "1.5"],
     r"drop_fraction \+ bad_fraction must be in"),
    ("fractions_sum_to_one", ["--synthetic", "static", "--drop-fraction", "0.5", "--bad-fraction", "0.5"],
     "must be in"),
    ("no_out", ["--synthetic", "static", "NO_OUT"], "Missing option '--out'"),
]


@pytest.mark.parametrize("case, args, message", COMPARE_OPTION_CASES, ids=[c[0] for c in COMPARE_OPTION_CASES])
def test_compare_bad_options(tmp_path, case, args, message):
    (tmp_path / "FILE").write_text("x")
    (tmp_path / "EMPTY").mkdir()
    subst = {"SEQ": str(tmp_path / "EMPTY"), "MISSING": str(tmp_path / "nope"), "FILE": str(tmp_path / "FILE"),
             "EMPTY": str(tmp_path / "EMPTY")}
    out = [] if "NO_OUT" in args else ["--out", str(tmp_path / "out")]
    result = runner.invoke(app, ["compare", *[subst.get(a, a) for a in args if a != "NO_OUT"], *out])
    assert_one_error_line(result, message)


def test_compare_output_path_that_is_a_file(tmp_path):
    (tmp_path / "taken").write_text("x")
    args = ["compare", "--synthetic", "static", "--duration-s", "1", "--out", str(tmp_path / "taken")]
    result = runner.invoke(app, args)
    assert_one_error_line(result, "taken: exists and is not a folder")


@pytest.mark.parametrize(
    "args, message",
    [(["nosuch"], "unknown benchmark 'nosuch'; choose from solver"),
     (["--repeats", "1"], "Invalid value for '--repeats'"),
     (["--repeats", "many"], "Invalid value for '--repeats'"),
     (["--json", "NODIR/x.json"], "cannot write a file there"),
     (["--json", "DIR"], "cannot write a file there")],
    ids=["unknown_benchmark", "too_few_repeats", "repeats_text", "json_in_missing_folder", "json_is_a_folder"],
)
def test_bench_rejects_bad_options_before_running(tmp_path, args, message):
    args = [a.replace("NODIR", str(tmp_path / "nodir")).replace("DIR", str(tmp_path)) for a in args]
    result = runner.invoke(app, ["bench", *args])
    assert_one_error_line(result, message)
    assert "median" not in result.stdout  # failed before timing anything


def test_demo_output_path_that_is_a_file(tmp_path):
    (tmp_path / "plot").write_text("x")
    result = runner.invoke(app, ["demo", "--out", str(tmp_path / "plot")])
    assert_one_error_line(result, "--out .*plot exists and is not a folder")


@pytest.mark.parametrize(
    "args, message",
    [(["nope"], r"No such command 'nope'. \(see 'uareme-fusion --help'\)"), (["--bogus"], "No such option: --bogus"),
     (["simulate"], "Missing argument")],
    ids=["unknown_command", "unknown_global_option", "simulate_without_scenario"],
)
def test_usage_errors_are_one_line(args, message):
    assert_one_error_line(runner.invoke(app, args), message)


@pytest.mark.slow
@pytest.mark.parametrize(
    "args, message",
    [(["solve", "missing.npy"], "missing.npy: no such file"), (["simulate", "room", "--frames", "x", "--out", "o"],
                                                              "Invalid value for '--frames'")],
    ids=["subprocess_input_error", "subprocess_usage_error"],
)
def test_real_process_exit_status_and_stderr(tmp_path, args, message):
    proc = subprocess.run([sys.executable, "-m", "uareme_fusion", *args], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr and re.search(message, lines[0]), proc.stderr
