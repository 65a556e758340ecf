"""`eval SOURCE --gt FILE [--gt-time-offset-s S]`: score a source without ground truth against a
TUM or EuRoC trajectory file (issue 16)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app


def _invoke(args):
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    return result


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """A simulated sequence, and a copy of its frames without groundtruth.txt, scene.json or IMU."""
    root = tmp_path_factory.mktemp("gt")
    _invoke(["simulate", "room", "--frames", "40", "--size", "96x72", "--out", str(root / "seq")])
    shutil.copytree(root / "seq" / "rgb", root / "plain" / "rgb")
    shutil.copy(root / "seq" / "rgb.txt", root / "plain" / "rgb.txt")
    shutil.copytree(root / "seq" / "normals", root / "plain" / "normals")
    return root


def _scores(root, name, *args):
    _invoke(["eval", *args, "--out", str(root / name)])
    return json.loads((root / name / "summary.json").read_text())


PLAIN = ("--cues", "normals")
"""Options of the runs on the plain folder: it has no intrinsics, and the line cue would search the
focal length on each of the first 30 frames (a few seconds per run), which the scores here do not need."""


@pytest.mark.slow
def test_tum_and_euroc_files_score_like_the_source_s_own_ground_truth(plain):
    own = _scores(plain, "own", str(plain / "seq"))
    gt_tum = plain / "seq" / "groundtruth.txt"
    tum = _scores(plain, "tum", str(plain / "plain"), "--gt", str(gt_tum), *PLAIN)
    rows = np.loadtxt(gt_tum)
    euroc = plain / "gt0.csv"  # ns, p xyz, q w x y z
    np.savetxt(euroc, np.column_stack([np.round(rows[:, 0] * 1e9), rows[:, 1:4], rows[:, 7], rows[:, 4:7]]),
               delimiter=",", fmt=["%d"] + ["%.9f"] * 7, header="timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z")
    from_euroc = _scores(plain, "euroc", str(plain / "plain"), "--gt", str(euroc), *PLAIN)
    # the plain folder has no IMU: compare with the source's own ground truth on the same frames
    no_imu = _scores(plain, "no_imu", str(plain / "plain"), "--gt", str(gt_tum), "--normals", "source", *PLAIN)
    assert own["are_deg"]["mean"] < 2.0
    for run in (tum, from_euroc):
        assert run["are_deg"] == pytest.approx(no_imu["are_deg"], abs=1e-6)
        assert run["tilt_deg"]["mean"] < 5.0


def test_gt_time_offset_puts_a_shifted_file_back_on_the_source_clock(plain):
    rows = np.loadtxt(plain / "seq" / "groundtruth.txt")
    shifted = plain / "late.txt"
    rows[:, 0] -= 0.4
    np.savetxt(shifted, rows, fmt="%.9f")
    reference = _scores(plain, "ref", str(plain / "plain"), "--gt", str(plain / "seq" / "groundtruth.txt"), *PLAIN)
    wrong = _scores(plain, "wrong", str(plain / "plain"), "--gt", str(shifted), *PLAIN)
    fixed = _scores(plain, "fixed", str(plain / "plain"), "--gt", str(shifted), "--gt-time-offset-s", "0.4", *PLAIN)
    assert fixed["are_deg"]["mean"] == pytest.approx(reference["are_deg"]["mean"], abs=1e-6)
    assert wrong["are_deg"]["mean"] > reference["are_deg"]["mean"] + 1.0


def test_missing_gt_file_is_one_error_line(plain):
    result = CliRunner().invoke(app, ["eval", str(plain / "plain"), "--gt", str(plain / "nope.txt"),
                                      "--out", str(plain / "x")])
    assert result.exit_code == 2 and "--gt" in result.output and "nope.txt" in result.output


def test_euroc_imu_log_with_its_gt_file_scores_like_the_dataset(shared_data, tmp_path):
    """A bare IMU log plus `--gt gt0/data.csv` gives the dataset folder's own scores (EuRoC V1_02)."""
    mav0 = shared_data / "euroc_v1_02_first40s" / "mav0"
    if not mav0.is_dir():
        pytest.skip("euroc_v1_02_first40s not in the development data")
    own = _scores(tmp_path, "own", str(mav0.parent), "--max-frames", "300")
    from_file = _scores(tmp_path, "file", str(mav0 / "imu0" / "data.csv"), "--gt", str(mav0 / "gt0" / "data.csv"),
                        "--max-frames", "300")
    assert own["frames_scored"] == from_file["frames_scored"] > 200
    assert from_file["tilt_deg"] == pytest.approx(own["tilt_deg"], abs=1e-9)
    assert from_file["are_deg"] == pytest.approx(own["are_deg"], abs=1e-9)
