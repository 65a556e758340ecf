"""Defaults chosen from what the source holds, and the image-side input mistakes, through the CLI:
an IMU-only source runs with the imu_only preset (a camera preset falls back to it, with a note) and
carries no VISUAL_MISSING flag; an IMU table is recognised by its content whatever its name; a file
that is neither a video nor a table is refused naming it; image names in ms / us are read as such;
EXIF orientation is applied; images listed in rgb.txt but missing are reported."""

from __future__ import annotations

import json
import re
import shutil

import cv2
import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.drivers.base import SourceInfo
from uareme_fusion.drivers.images import ImageSource
from uareme_fusion.io.images import read_image
from uareme_fusion.pipeline.stages import mekf_preset_for
from uareme_fusion.sim.normal_maps import manhattan_normal_map

runner = CliRunner()


def run_cli(*args):
    result = runner.invoke(app, [str(a) for a in args])
    return result


def summary_of(out):
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("requested, has_frames, chosen, noted", [
    (None, True, "handheld", False), ("vehicle", True, "vehicle", False), (None, False, "imu_only", False),
    ("vehicle", False, "imu_only", True), ("building", False, "imu_only", True), ("handheld", False, "imu_only", True),
    ("imu_only", False, "imu_only", False), ("my.yaml", False, "my.yaml", False)])
def test_preset_follows_the_source(requested, has_frames, chosen, noted):
    preset, note = mekf_preset_for(requested, SourceInfo(name="src", has_frames=has_frames))
    assert preset == chosen and (note is not None) == noted


@pytest.mark.parametrize("requested, platform, chosen, noted", [
    (None, "vehicle", "vehicle", True), ("handheld", "vehicle", "handheld", False), (None, None, "handheld", False),
    (None, "handheld", "handheld", False),
    (None, "building", "building", True)])
def test_preset_follows_the_platform_the_source_states(requested, platform, chosen, noted):
    preset, note = mekf_preset_for(requested, SourceInfo(name="src", platform=platform))
    assert preset == chosen and (note is not None) == noted


def test_a_simulated_bus_folder_says_vehicle_and_a_bad_platform_is_named(tmp_path):
    from uareme_fusion.drivers.tum import TumSource
    from uareme_fusion.errors import InputError
    from uareme_fusion.sim.dataset import write_sequence
    from uareme_fusion.sim.options import SequenceOptions

    write_sequence("bus", tmp_path / "bus", SequenceOptions(frames=3, width=32, height=24))
    with TumSource(tmp_path / "bus") as src:
        assert src.info.platform == "vehicle"
    scene = tmp_path / "bus" / "scene.json"
    scene.write_text(scene.read_text().replace('"platform": "vehicle"', '"platform": "boat"'))
    with pytest.raises(InputError, match=r"scene.json: platform must be one of building, handheld, vehicle, got 'boat'"):
        TumSource(tmp_path / "bus")


@pytest.fixture
def broad_trial(shared_data):
    return shared_data / "broad_subset" / "02_undisturbed_slow_rotation_B.hdf5"


def test_broad_default_equals_imu_only_and_vehicle_is_no_worse(tmp_path, broad_trial):
    tilts = {}
    for name, extra in (("default", []), ("imu_only", ["--preset", "imu_only"]), ("vehicle", ["--preset", "vehicle"])):
        result = run_cli("eval", broad_trial, "--out", tmp_path / name, "--max-frames", 900, *extra)
        assert result.exit_code == 0, result.output
        summary = summary_of(tmp_path / name)
        assert summary["mekf_preset"] == "imu_only" and "VISUAL_MISSING" not in summary["status_counts"]
        tilts[name] = summary["tilt_deg"]
    assert tilts["default"] == tilts["imu_only"] == tilts["vehicle"]
    assert tilts["default"]["mean"] < 1.0
    assert any("preset 'vehicle' tunes camera + IMU fusion" in note for note in summary["notes"])


def test_broad_benchmark_needs_trials(tmp_path):
    result = run_cli("bench", "broad", "--data", tmp_path)
    assert result.exit_code == 2 and re.search(r"--data .*: holds no BROAD .hdf5 trials", result.stderr)


def test_an_imu_table_is_recognised_by_content_whatever_its_name(tmp_path, shared_data):
    table = tmp_path / "MH04.txt"
    shutil.copy(shared_data / "euroc_v1_02_first40s" / "mav0" / "imu0" / "data.csv", table)
    result = run_cli("run", table, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    summary = summary_of(tmp_path / "out")
    assert summary["frames"] == 0 and summary["imu_samples"] > 7000 and summary["mekf_preset"] == "imu_only"
    assert summary["status_counts"] == {} and summary["input_fixes"] == []


def test_whitespace_separated_imu_table_reads(tmp_path):
    rows = "".join(f"{1_000_000_000 + 5_000_000 * i} 0.001 0.002 0.003 0.0 0.0 9.81\n" for i in range(300))
    (tmp_path / "imu.log").write_text("# t wx wy wz ax ay az\n" + rows)
    result = run_cli("run", tmp_path / "imu.log", "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert summary_of(tmp_path / "out")["imu_samples"] == 300


@pytest.mark.parametrize("name, content, message", [
    ("notes.txt", "hello world\nhello again\n", r"notes.txt is not an EuRoC IMU file: line 1 has 2 column"),
    ("clip.mov", "just some text\n", r"clip.mov: neither a video \(it holds text\) nor an IMU table"),
    ("blob.bin", b"\x00\x01\x02garbage" * 50, r"video .*blob.bin: OpenCV cannot open it"),
])
def test_a_file_that_is_neither_video_nor_table_is_refused_naming_it(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content) if isinstance(content, bytes) else path.write_text(content)
    result = run_cli("run", path, "--out", tmp_path / "out")
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and re.search(message, lines[0]), result.stderr


@pytest.mark.parametrize("unit, scale, start", [("ms", 1_000, 1_700_000_000_000), ("ms", 1_000, 0),
                                                ("us", 1_000_000, 1_700_000_000_000_000), ("us", 1_000_000, 0)])
def test_image_names_in_ms_or_us_are_read_with_their_unit(tmp_path, unit, scale, start):
    frames = tmp_path / "frames"
    maps = tmp_path / "maps"
    frames.mkdir()
    maps.mkdir()
    rng = np.random.default_rng(1)
    for i in range(6):
        stamp = start + round(i * scale / 30)
        cv2.imwrite(str(frames / f"{stamp}.png"), np.full((12, 16, 3), 80, np.uint8))
        np.save(maps / f"{i:03d}.npy", manhattan_normal_map(np.eye(3), rng, height=12, width=16, noise_deg=3).normals)
    result = run_cli("run", frames, "--normals", maps, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    summary = summary_of(tmp_path / "out")
    assert summary["source_info"]["fps"] == pytest.approx(30.0, rel=0.02)
    assert f"image names read as timestamps in {unit}" in summary["notes"][0]
    assert f"note: {frames}: image names read as timestamps in {unit}" in result.stderr


def test_frame_numbers_stay_frame_numbers(tmp_path):
    for i in (1, 2, 3, 10):
        cv2.imwrite(str(tmp_path / f"{i}.png"), np.zeros((4, 4, 3), np.uint8))
    src = ImageSource(tmp_path)
    np.testing.assert_allclose(src.t_s, np.array([1, 2, 3, 10]) / 30.0)
    assert src.report() == ([], [])


def portrait_photo(path, width=40, height=24):
    """A landscape-stored JPEG whose EXIF says 'rotate 90 degrees clockwise to view' (a phone held upright):
    left half dark, right half bright as stored, so upright the top is dark."""
    stored = np.zeros((height, width, 3), np.uint8)
    stored[:, width // 2:] = 230
    image = Image.fromarray(stored)
    exif = image.getexif()
    exif[0x0112] = 6
    image.save(path, exif=exif, quality=95)


def test_exif_orientation_is_applied(tmp_path):
    portrait_photo(tmp_path / "phone.jpg")
    image = read_image(tmp_path / "phone.jpg")
    assert image.shape[:2] == (40, 24)
    assert image[:20].mean() < 30 and image[20:].mean() > 200  # stored left -> upright top


@pytest.mark.slow
def test_exif_orientation_through_the_normals_command(tmp_path):
    portrait_photo(tmp_path / "phone.jpg")
    result = run_cli("normals", tmp_path / "phone.jpg", "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert cv2.imread(str(tmp_path / "out" / "phone_normals.png")).shape[:2] == (40, 24)


def test_images_listed_but_missing_are_reported(tmp_path):
    folder = tmp_path / "seq"
    rgb = folder / "rgb"
    rgb.mkdir(parents=True)
    maps = tmp_path / "maps"
    maps.mkdir()
    rng = np.random.default_rng(2)
    lines = []
    for i in range(5):
        name = f"rgb/{i / 30:.6f}.png"
        lines.append(f"{i / 30:.6f} {name}\n")
        if i != 2:
            cv2.imwrite(str(folder / name), np.full((12, 16, 3), 90, np.uint8))
            np.save(maps / f"{i:03d}.npy", manhattan_normal_map(np.eye(3), rng, height=12, width=16).normals)
    (folder / "rgb.txt").write_text("# timestamp filename\n" + "".join(lines))
    result = run_cli("run", folder, "--normals", maps, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    message = f"{folder}: 1 listed rgb images do not exist and were left out"
    assert f"note: {message}" in result.stderr and summary_of(tmp_path / "out")["notes"] == [message]
