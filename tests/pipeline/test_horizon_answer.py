"""One answer per frame (solver/horizon_estimate.py, pipeline/single_image.py): the horizon line, up_c and
R_cm agree; the horizon's std and `horizon_known`; bad input gives a finite answer or no horizon."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.overlay.horizon import draw_horizon, horizon_line, off_screen_note
from uareme_fusion.pinhole import centred_K
from uareme_fusion.solver.horizon_estimate import (
    HorizonUncertainty,
    aligned_rotation,
    horizon_known,
    horizon_uncertainty,
    up_axis,
    up_covariance,
)

UP_LEVEL_C = np.array([0.0, -1.0, 0.0])


def test_aligned_rotation_puts_its_up_axis_on_up_by_the_smallest_turn():
    R = Rotation.from_rotvec([0.2, -0.4, 0.1]).as_matrix()
    up = Rotation.from_rotvec([0.05, 0.0, -0.03]).apply(R[:, 1])
    R2 = aligned_rotation(R, up)
    k, sign = up_axis(R2, up)
    assert np.allclose(sign * R2[:, k], up / np.linalg.norm(up), atol=1e-12)
    assert np.allclose(R2.T @ R2, np.eye(3), atol=1e-12) and np.linalg.det(R2) == pytest.approx(1.0)
    turn = np.degrees(np.linalg.norm(Rotation.from_matrix(R2 @ R.T).as_rotvec()))
    assert turn == pytest.approx(np.degrees(np.arccos(np.clip(R[:, 1] @ up / np.linalg.norm(up), -1, 1))), abs=1e-6)


def test_horizon_std_of_a_level_camera_is_f_times_the_pitch_std_and_the_roll_std():
    f, sigma = 500.0, 0.01
    K = centred_K(f, 480, 640)
    R = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # Manhattan z = up = camera -y
    up = R[:, 2]
    assert np.allclose(up, UP_LEVEL_C)
    cov = np.diag([sigma**2, (2 * sigma) ** 2, 1.0])  # delta about m-x (camera x: pitch), m-y (camera z: roll)
    u = horizon_uncertainty(up, up_covariance(R, cov, up), K, 480, 640)
    assert u.offset_std_px == pytest.approx(f * sigma, rel=1e-3)
    assert u.angle_std_deg == pytest.approx(np.degrees(2 * sigma), rel=1e-3)
    assert u.in_image and u.centre_offset_px == pytest.approx(0.0, abs=1e-6)
    assert horizon_known(u, True, 480) and not horizon_known(u, False, 480)
    wide = HorizonUncertainty(100.0, 1.0, 0.0, True)
    assert not horizon_known(wide, True, 480)


def test_off_screen_horizon_is_reported_with_where_it_lies():
    K = centred_K(500.0, 480, 640)
    for pitch_deg, where in ((60.0, "below"), (-60.0, "above")):  # up tilted forward: the camera looks up
        up = Rotation.from_rotvec([-np.radians(pitch_deg), 0, 0]).apply(UP_LEVEL_C)
        u = horizon_uncertainty(up, np.eye(3) * 1e-6, K, 480, 640)
        assert not u.in_image
        assert u.centre_offset_px == pytest.approx(np.sign(-pitch_deg) * 500 * np.tan(np.radians(60)), rel=1e-6)
        note = off_screen_note(up, K, 480, 640)
        assert note == f"horizon off-screen, 866 px {where} the centre"
        image = draw_horizon(np.zeros((480, 640, 3), np.uint8), up, K)
        assert image[:40].any() and not image[100:].any()  # the note only, top-left


def test_band_drawn_for_the_std_and_nothing_when_unknown():
    K = centred_K(500.0, 480, 640)
    grey = np.full((480, 640, 3), 100, np.uint8)
    banded = draw_horizon(grey, UP_LEVEL_C, K, std_px=20.0)
    column = banded[:, 100].astype(int)
    tinted = np.flatnonzero(np.any(column != 100, axis=1))
    assert tinted.min() <= 239.5 - 18 and tinted.max() >= 239.5 + 18 and tinted.max() - tinted.min() < 50
    unknown = draw_horizon(grey, UP_LEVEL_C, K, std_px=20.0, known=False)
    assert np.all(unknown[100:] == 100)  # no line, the note top-left only


def _check_one_answer(doc: dict) -> None:
    """The JSON of one image: up_c is a signed column of R_cm, and the horizon is K^-T up_c."""
    R = np.array(doc["R_cm"])
    up = np.array(doc["up_c"])
    assert np.max(np.abs(R.T @ up)) == pytest.approx(1.0, abs=1e-9)
    assert np.allclose(np.array(doc["q_cm_xyzw"]), Rotation.from_matrix(R).as_quat(), atol=1e-9) or \
        np.allclose(np.array(doc["q_cm_xyzw"]), -Rotation.from_matrix(R).as_quat(), atol=1e-9)
    if doc["horizon_known"]:
        assert np.allclose(doc["horizon"], horizon_line(up, np.array(doc["K"])), atol=1e-9)
        assert doc["horizon_std_px"] is not None and doc["horizon_std_px"] > 0
    else:
        assert doc["horizon"] is None


@pytest.mark.slow
def test_one_answer_on_the_dev_images(shared_data):
    """Real photos of every dev folder (every 12th: runways, cities, corridors, an office): line, up and
    rotation from one estimate (the runway photo whose Atlanta line stood 60 deg from its rotation's up)."""
    from uareme_fusion.pipeline.single_image import ImageAnalyser

    paths = (sorted((shared_data / "horizon_uav" / "images").glob("*.jpg"))[::12]
             + sorted((shared_data / "eurasian_cities").glob("*.jpg"))[::12]
             + sorted((shared_data / "icsl_corridor" / "rgb").glob("*.png"))[::12]
             + sorted((shared_data / "icl_nuim_office_kt3" / "rgb").glob("*.png"))[::12])
    analyser = ImageAnalyser()
    for path in paths:
        _check_one_answer(json.loads(json.dumps(analyser.analyse(path).as_dict())))


def _bad_images() -> dict:
    rng = np.random.default_rng(1)
    ys, xs = np.mgrid[0:480, 0:640]
    sky = np.stack([200 + 0 * xs + ys / 20, 215 + 0 * xs, 240 + 0 * xs], -1)
    return {"wall": np.full((480, 640, 3), 180, np.uint8),
            "floor": cv2.GaussianBlur(np.clip(100 + rng.normal(0, 40, (480, 640, 3)), 0, 255).astype(np.uint8), (0, 0), 2),
            "night": np.clip(rng.normal(6, 3, (480, 640, 3)), 0, 255).astype(np.uint8),
            "all_sky": np.clip(sky, 0, 255).astype(np.uint8)}


@pytest.mark.parametrize("name", ["wall", "floor", "night", "all_sky"])
def test_no_horizon_without_structure_or_sky(tmp_path, name):
    """A close-up of a wall or floor, a night shot, a photo of sky only: `horizon_known` false, no line,
    finite numbers, and the overlay says so."""
    from uareme_fusion.pipeline.single_image import ImageAnalyser, image_overlay

    path = tmp_path / f"{name}.png"
    cv2.imwrite(str(path), _bad_images()[name][..., ::-1])
    result = ImageAnalyser().analyse(path)
    doc = result.as_dict()
    assert doc["horizon_known"] is False and doc["horizon"] is None
    assert all(math.isfinite(x) for x in doc["up_c"] + doc["std_deg"])
    _check_one_answer(doc)
    overlay = image_overlay(result, panes=False)
    assert np.array_equal(overlay[60:-40], result.rgb[60:-40])  # no line, no axes: notes top and bottom only
    assert not np.array_equal(overlay[:60], result.rgb[:60])


def test_rotated_and_fisheye_drone_photo_is_right_or_wide(shared_data, tmp_path):
    """A real drone photo turned 90 deg (portrait held sideways) and through a fisheye-like distortion:
    the horizon turns with it, or the answer is declined or wide (never a confident wrong line)."""
    import csv

    from uareme_fusion.benchmarks.horizon_uav import label_line, roll_error_deg
    from uareme_fusion.pipeline.single_image import ImageAnalyser

    folder = shared_data / "horizon_uav"
    row = list(csv.DictReader((folder / "label.csv").open()))[5]
    rgb = cv2.cvtColor(cv2.imread(str(folder / "images" / row["filename"])), cv2.COLOR_BGR2RGB)
    h, w = rgb.shape[:2]
    truth = label_line(float(row["slope"]), float(row["offset"]), h)
    # rotating the image 90 deg clockwise maps (x, y) to (h - 1 - y, x): the line's normal turns with it
    turned = np.ascontiguousarray(np.rot90(rgb, k=-1))
    a, b, c = truth
    truth_turned = np.array([b, -a, c + a * (h - 1)])  # a x + b y + c with x = y', y = h - 1 - x'
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    x, y = (xs - w / 2) / (w / 2), (ys - h / 2) / (h / 2)
    k = 1 + 0.6 * (x * x + y * y)
    fish = cv2.remap(rgb, x * k * w / 2 + w / 2, y * k * h / 2 + h / 2, cv2.INTER_LINEAR)
    analyser = ImageAnalyser()
    for name, image, line in (("turned", turned, truth_turned), ("fisheye", fish, truth)):
        path = tmp_path / f"{name}.png"
        cv2.imwrite(str(path), image[..., ::-1])
        doc = analyser.analyse(path).as_dict()
        _check_one_answer(doc)
        if doc["horizon_known"]:
            roll = roll_error_deg(doc["horizon"], line)
            assert roll < max(5.0, 3.0 * doc["horizon_angle_std_deg"]), (name, roll, doc["horizon_angle_std_deg"])


@pytest.mark.slow
def test_stream_of_a_rolling_drone_photo_follows_the_sky(shared_data, tmp_path):
    """A real drone photo turned 0.7 deg more each frame (12 frames, centre crop), `run` with the EKF and
    no intrinsics: every frame's horizon within 2 deg and 0.05 H of the turned label."""
    import csv

    from uareme_fusion.scoring.horizon import horizon_error
    from uareme_fusion.benchmarks.horizon_uav import label_line, roll_error_deg
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.session import run_to_folder

    folder = shared_data / "horizon_uav"
    row = list(csv.DictReader((folder / "label.csv").open()))[40]
    bgr = cv2.imread(str(folder / "images" / row["filename"]))
    truth = label_line(float(row["slope"]), float(row["offset"]), bgr.shape[0])
    frames = tmp_path / "frames"
    frames.mkdir()
    truths = []
    for i in range(12):
        A = np.vstack([cv2.getRotationMatrix2D((239.5, 239.5), 0.7 * i, 1.0), [0, 0, 1]])
        cv2.imwrite(str(frames / f"{i:04d}.png"), cv2.warpAffine(bgr, A[:2], (480, 480))[80:400, 80:400])
        to_crop = np.array([[1.0, 0, -80], [0, 1, -80], [0, 0, 1]]) @ A
        line = np.linalg.inv(to_crop).T @ truth
        truths.append(line / np.hypot(*line[:2]))
    out = tmp_path / "run"
    summary = run_to_folder(str(frames), str(out), RunConfig(normals="learned"), command="run")
    K = np.array(summary["intrinsics"]["K"])
    rows = list(csv.DictReader((out / "estimates.csv").open()))
    assert len(rows) == 12
    for est, line in zip(rows, truths):
        up = np.array([float(est["up_x"]), float(est["up_y"]), float(est["up_z"])])
        drawn = horizon_line(up, K)
        assert roll_error_deg(drawn, line) < 2.0 and horizon_error(drawn, line, 320, 320) < 0.05
