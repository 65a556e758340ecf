"""`compare SOURCE --normals ...` on any source: visual rotations once, then every backend (issue 16)."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from uareme_fusion.cli import app


def test_compare_any_source_with_normals_option(tmp_path):
    result = CliRunner().invoke(app, ["compare", "sim:room", "--normals", "source", "--max-frames", "30",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    doc = json.loads((tmp_path / "compare.json").read_text())
    assert doc["frames"] == 30 and doc["has_imu"] and doc["has_ground_truth"]
    rows = doc["backends"]
    assert set(rows) == {"single", "smoother", "smoother-gyro", "mekf"}
    for name in ("single", "mekf", "smoother-gyro"):
        assert rows[name]["frames"] == 30 and rows[name]["are_deg_mean"] < 2.0, (name, rows[name])
    assert rows["mekf"]["tilt_deg_mean"] < 2.0  # gravity from the IMU


def test_compare_bad_normals_is_one_error_line(tmp_path):
    result = CliRunner().invoke(app, ["compare", "sim:room", "--normals", "nonsense", "--max-frames", "3",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--normals" in result.output


def test_compare_cues_lines_only(tmp_path):
    result = CliRunner().invoke(app, ["compare", "sim:room", "--cues", "lines", "--max-frames", "10",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    doc = json.loads((tmp_path / "compare.json").read_text())
    assert doc["frames"] == 10
    assert any("cues lines" in note for note in doc["notes"])  # the run says which cues it used
    # The rendered room has few long edges: segments alone give about 10 deg here (normals: < 2).
    assert doc["backends"]["single"]["are_deg_mean"] < 20.0


def test_compare_bad_cues_is_one_error_line(tmp_path):
    result = CliRunner().invoke(app, ["compare", "sim:room", "--cues", "edges", "--max-frames", "3",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--cues" in result.output and "normals, lines" in result.output
