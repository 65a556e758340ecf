"""Defaults right for the input (issue 30 item 4), through the real CLI on a simulated RGB-D folder:
`--normals auto` takes the depth of a folder with depth maps and intrinsics and says so; `eval`'s
table says when tilt is measured after the constant alignment, with the unaligned figure beside it."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app


def _invoke(args):
    result = CliRunner().invoke(app, args, env={"COLUMNS": "200"})  # table rows unwrapped
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def rgbd_folder(tmp_path_factory):
    """A simulated room as a real RGB-D folder holds it: rgb, depth, ground truth, intrinsics, no normals."""
    root = tmp_path_factory.mktemp("rgbd") / "room"
    _invoke(["simulate", "room", "--frames", "12", "--size", "128x96", "--out", str(root)])
    shutil.rmtree(root / "normals")
    shutil.rmtree(root / "imu0")
    return root


def _eval(folder, out, *extra):
    output = _invoke(["eval", str(folder), "--out", str(out), "--backend", "single", *extra])
    return json.loads((out / "summary.json").read_text()), output


def test_auto_normals_use_the_depth_of_an_rgbd_folder_and_say_so(rgbd_folder, tmp_path):
    auto, auto_out = _eval(rgbd_folder, tmp_path / "auto")
    depth, _ = _eval(rgbd_folder, tmp_path / "depth", "--normals", "depth")
    assert auto["normals"] == "auto (depth)" and auto["frames_without_depth"] == 0
    notes = [line for line in auto_out.splitlines() if line.startswith("note: --normals auto")]
    assert len(notes) == 1 and "depth" in notes[0] and "--normals learned" in notes[0]
    assert auto["normals_note"] in auto["notes"] and "has depth maps and intrinsics" in auto["normals_note"]
    # the same estimates as asking for depth by name
    assert auto["are_deg"]["mean"] == pytest.approx(depth["are_deg"]["mean"], abs=1e-9)
    assert auto["are_deg"]["mean"] < 2.0 and "normals_note" not in depth


def test_auto_normals_keep_a_folders_exact_normals_and_a_folder_without_depth_gets_no_depth_note(rgbd_folder, tmp_path):
    exact = tmp_path / "exact"
    _invoke(["simulate", "room", "--frames", "6", "--size", "128x96", "--out", str(exact)])
    summary, output = _eval(exact, tmp_path / "exact_out")
    assert summary["normals"] == "auto (source)" and "normals_note" not in summary
    assert "note: --normals auto" not in output


def test_eval_says_when_tilt_is_after_the_alignment_and_shows_the_unaligned_tilt(rgbd_folder, tmp_path):
    aligned, aligned_out = _eval(rgbd_folder, tmp_path / "aligned")  # the simulator's world: z up
    assert "tilt_unaligned_deg" not in aligned and "after the constant alignment" not in aligned_out
    folder = tmp_path / "not_up"
    shutil.copytree(rgbd_folder, folder)
    meta = json.loads((folder / "scene.json").read_text())
    (folder / "source.json").write_text(json.dumps({"K": meta["K"], "gravity_aligned": False}))
    summary, output = _eval(folder, tmp_path / "not_up_out")
    assert "not gravity-aligned" in summary["evaluation_note"]
    assert "after the constant" in output and "without alignment" in output
    # the reference here is in fact z up: the tilt without alignment is the aligned one's size
    assert summary["tilt_unaligned_deg"]["mean"] == pytest.approx(aligned["tilt_deg"]["mean"], abs=0.5)
    assert summary["tilt_deg"]["mean"] <= summary["tilt_unaligned_deg"]["mean"] + 0.5


def _depth_config(folder):
    from uareme_fusion.drivers.tum import TumSource
    from uareme_fusion.pipeline.stages import make_normal_estimator

    with TumSource(folder) as source:
        return make_normal_estimator("depth", source.info).estimator.config


def test_rendered_depth_counts_more_errors_per_window_and_a_real_sensor_folder_is_capped(rgbd_folder, tmp_path):
    """A simulated folder (scene.json) has rendered depth: 20 independent errors per window area (no cap).
    The same files in a TUM-named folder without scene.json are a real sensor's: the 60-region cap."""
    rendered = _depth_config(rgbd_folder)
    assert rendered.max_independent_regions == float("inf") and rendered.errors_per_window_area == 20.0
    real = tmp_path / "rgbd_dataset_freiburg1_copy"
    shutil.copytree(rgbd_folder, real)
    (real / "scene.json").unlink()
    sensor = _depth_config(real)
    assert sensor.max_independent_regions == 60.0 and sensor.errors_per_window_area == 1.0
