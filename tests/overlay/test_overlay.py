"""Overlay geometry and drawing: horizon, vanishing points, ground mask, panes (numbers, not pictures)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.errors import InputError
from uareme_fusion.io.normal_maps import normals_to_rgb
from uareme_fusion.overlay import (
    assumed_fov_note,
    assumed_K,
    draw_ground,
    draw_horizon,
    draw_manhattan_axes,
    draw_overlay,
    ground_mask,
    horizon_line,
    horizon_segment,
    intrinsics_or_assumed,
    manhattan_vanishing_points,
    on_sky_side,
    side_by_side,
)
from uareme_fusion.rotations import up_in_camera
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.types import NormalMap

H, W = 480, 640
# Principal point off the image centre, so that "through the principal point" is a real check.
K = np.array([[500.0, 0.0, 300.0], [0.0, 500.0, 200.0], [0.0, 0.0, 1.0]])
R_WC_LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""A level camera looking along world +x: camera x (right) = world -y, y (down) = world -z."""


def camera_rotated(axis: str, angle_deg: float) -> np.ndarray:
    """R_wc of the level camera turned by `angle_deg` about its own `axis` (right-hand rule)."""
    return R_WC_LEVEL @ Rotation.from_euler(axis, angle_deg, degrees=True).as_matrix()


# ---------------------------------------------------------------- intrinsics


def test_assumed_K_has_the_horizontal_fov_and_a_centred_principal_point():
    K_a = assumed_K(H, W, fov_deg=60.0)
    assert K_a[0, 0] == pytest.approx(320.0 / math.tan(math.radians(30.0)))
    assert K_a[1, 1] == K_a[0, 0]
    assert (K_a[0, 2], K_a[1, 2]) == (319.5, 239.5)
    # The left and right image borders (pixel edges at -0.5 and W - 0.5) are 30 deg off axis.
    ray = np.linalg.solve(K_a, [W - 0.5, 239.5, 1.0])
    assert math.degrees(math.atan2(ray[0], ray[2])) == pytest.approx(30.0)


def test_intrinsics_or_assumed():
    K_out, assumed = intrinsics_or_assumed(None, H, W, 90.0)
    assert assumed and K_out[0, 0] == pytest.approx(320.0)
    K_out, assumed = intrinsics_or_assumed(K, H, W, 90.0)
    assert not assumed and np.array_equal(K_out, K)
    assert assumed_fov_note(60.0) == "assumed FOV 60 deg"


@pytest.mark.parametrize(
    "K_bad, match",
    [(np.eye(2), r"shape \(3, 3\)"), (np.diag([-1.0, 1.0, 1.0]), "fx, fy > 0"), (np.full((3, 3), np.nan), "non-finite")],
)
def test_bad_intrinsics_are_input_errors(K_bad, match):
    with pytest.raises(InputError, match=match):
        intrinsics_or_assumed(K_bad, H, W)


def test_bad_fov_is_an_input_error():
    with pytest.raises(InputError, match="fov_deg"):
        assumed_K(H, W, fov_deg=180.0)


# ---------------------------------------------------------------- horizon geometry


def test_level_camera_horizon_is_the_principal_point_row_left_to_right_with_sky_above():
    up_c = up_in_camera(R_WC_LEVEL)
    np.testing.assert_allclose(up_c, [0.0, -1.0, 0.0], atol=1e-12)
    (x0, y0), (x1, y1) = horizon_segment(up_c, K, H, W)
    assert (x0, x1) == pytest.approx((0.0, W - 1.0))
    assert (y0, y1) == pytest.approx((200.0, 200.0))
    assert on_sky_side(np.array([[100.0, 190.0], [100.0, 210.0]]), up_c, K).tolist() == [True, False]
    # The line is scaled to pixel units: a pixel 10 rows above it is at signed distance +10.
    assert horizon_line(up_c, K) @ [100.0, 190.0, 1.0] == pytest.approx(10.0)


@pytest.mark.parametrize("fy", [500.0, 600.0])
def test_rolled_camera_gives_slope_tan_roll_through_the_principal_point(fy):
    # +10 deg about the optical axis: the camera's right side goes down (its x axis gains -z in the world).
    R_wc = camera_rotated("z", 10.0)
    assert R_wc[2, 0] < 0
    K_roll = K.copy()
    K_roll[1, 1] = fy
    (x0, y0), (x1, y1) = horizon_segment(up_in_camera(R_wc), K_roll, H, W)
    # The world tilts the other way in the image: the horizon rises to the right (y is down).
    assert (y1 - y0) / (x1 - x0) == pytest.approx(-math.tan(math.radians(10.0)) * fy / 500.0)
    y_at_cx = y0 + (300.0 - x0) * (y1 - y0) / (x1 - x0)
    assert y_at_cx == pytest.approx(200.0)
    assert x0 < x1  # still left to right: the sky is above
    assert on_sky_side(np.array([300.0, 150.0]), up_in_camera(R_wc), K_roll)


@pytest.mark.parametrize("pitch_deg", [5.0, 20.0])
def test_camera_pitched_down_moves_the_horizon_up_by_f_tan_pitch(pitch_deg):
    R_wc = camera_rotated("x", -pitch_deg)
    assert R_wc[2, 2] < 0  # the optical axis points below the horizontal
    (x0, y0), (x1, y1) = horizon_segment(up_in_camera(R_wc), K, H, W)
    expected_y = 200.0 - 500.0 * math.tan(math.radians(pitch_deg))
    assert (y0, y1) == pytest.approx((expected_y, expected_y))
    assert (x0, x1) == pytest.approx((0.0, W - 1.0))


def test_upside_down_camera_runs_right_to_left_with_sky_below():
    up_c = up_in_camera(camera_rotated("z", 180.0))
    (x0, y0), (x1, y1) = horizon_segment(up_c, K, H, W)
    assert (x0, x1) == pytest.approx((W - 1.0, 0.0))
    assert y0 == pytest.approx(200.0)
    assert on_sky_side(np.array([100.0, 300.0]), up_c, K)


@pytest.mark.parametrize(
    "up_c",
    [
        [0.0, 0.0, -1.0],  # looking straight down: the horizon is the line at infinity
        [0.0, 0.0, 1.0],  # straight up
        up_in_camera(camera_rotated("x", -70.0)),  # steeply down: the horizon is above the image
    ],
)
def test_horizon_missing_the_image_is_none(up_c):
    assert horizon_segment(np.asarray(up_c), K, H, W) is None


def test_bad_up_vector_is_an_input_error():
    with pytest.raises(InputError, match="up_c"):
        horizon_segment(np.zeros(3), K, H, W)
    with pytest.raises(InputError, match="up_c"):
        horizon_segment(np.ones(4), K, H, W)


# ---------------------------------------------------------------- vanishing points


def test_vanishing_points_of_a_yawed_camera_land_where_K_predicts():
    # Camera turned 30 deg about its y axis relative to the room: Manhattan axes in the camera.
    R_cm = Rotation.from_euler("y", 30.0, degrees=True).as_matrix()
    points = manhattan_vanishing_points(R_cm, K)
    t30 = math.tan(math.radians(30.0))
    np.testing.assert_allclose(points[2], [300.0 + 500.0 * t30, 200.0])
    np.testing.assert_allclose(points[0], [300.0 - 500.0 / t30, 200.0])
    assert np.all(np.isnan(points[1]))  # the vertical axis is parallel to the image plane


def test_vanishing_points_are_on_their_axes_rays_and_horizontal_ones_on_the_horizon():
    rng = np.random.default_rng(7)
    for _ in range(5):
        R_wc = R_WC_LEVEL @ Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
        R_cm = R_wc.T  # Manhattan frame = world frame: m's z axis is up
        points = manhattan_vanishing_points(R_cm, K)
        rays = np.linalg.solve(K, np.c_[points, np.ones(3)].T)  # (3, 3 axes)
        rays /= np.linalg.norm(rays, axis=0)
        np.testing.assert_allclose(np.abs(np.sum(rays * R_cm, axis=0)), 1.0, atol=1e-9)
        line = horizon_line(up_in_camera(R_wc), K)
        np.testing.assert_allclose(np.c_[points[:2], np.ones(2)] @ line, 0.0, atol=1e-6)


# ---------------------------------------------------------------- ground mask


def test_ground_mask_recovers_the_floor_of_a_synthetic_map_and_ignores_kappa_zero():
    R_wc = camera_rotated("x", -25.0)
    up_c = up_in_camera(R_wc)
    R_cm = R_wc.T  # one Manhattan axis is up
    common = dict(height=120, width=160, outlier_fraction=0.1, n_planes=10)
    noisy = manhattan_normal_map(R_cm, np.random.default_rng(3), noise_deg=3.0, **common)
    exact = manhattan_normal_map(R_cm, np.random.default_rng(3), noise_deg=0.0, **common)  # same planes, outliers
    kappa = noisy.kappa.copy()
    kappa[40:80, 40:80] = 0.0
    truth = (exact.normals @ up_c > 0.999) & (exact.kappa == 1.0) & (kappa > 0)
    assert 0.1 < truth.mean() < 0.6  # the scene really has floor and walls

    mask, score = ground_mask(NormalMap(noisy.normals, kappa), up_c)
    iou = (mask & truth).sum() / (mask | truth).sum()
    assert iou > 0.95
    assert not mask[40:80, 40:80].any()
    assert np.all(score[kappa == 0] == 0.0)
    assert score.dtype == np.float32 and 0.0 <= score.min() and score.max() <= 0.5  # kappa 1 -> trust 1/2


def test_ground_mask_threshold_and_confidence_weighting_numbers():
    up_c = np.array([0.0, -1.0, 0.0])
    angles = np.radians([0.0, 14.0, 16.0, 0.0, 0.0, 0.0])
    normals = np.stack([np.zeros(6), -np.cos(angles), np.sin(angles)], axis=-1)[None]  # (1, 6, 3)
    normals[0, 5] = np.nan
    kappa = np.array([[3.0, 3.0, 3.0, 0.4, 0.0, 3.0]])
    mask, score = ground_mask(NormalMap(normals, kappa), up_c, threshold_deg=15.0, min_kappa=0.5, kappa_half=1.0)
    assert mask.tolist() == [[True, True, False, False, False, False]]
    np.testing.assert_allclose(score[0], [0.75, 0.75 * math.cos(angles[1]), 0.75 * math.cos(angles[2]), 0.4 / 1.4, 0, 0],
                               rtol=1e-6)


def test_ground_mask_bad_input():
    normal_map = NormalMap(np.zeros((4, 5, 3)), np.ones((4, 4)))
    with pytest.raises(InputError, match="kappa"):
        ground_mask(normal_map, np.array([0.0, -1.0, 0.0]))
    with pytest.raises(InputError, match="threshold_deg"):
        ground_mask(NormalMap(np.zeros((4, 5, 3)), np.ones((4, 5))), np.array([0.0, -1.0, 0.0]), threshold_deg=90.0)


# ---------------------------------------------------------------- drawing


def grey_image(height=H, width=W):
    return np.full((height, width, 3), 100, np.uint8)


def test_draw_horizon_keeps_shape_and_input_and_colours_the_line():
    rgb = grey_image()
    out = draw_horizon(rgb, np.array([0.0, -1.0, 0.0]), K)
    assert out.shape == rgb.shape and out.dtype == np.uint8
    assert np.all(rgb == 100)  # the input is untouched
    assert out[200, 100].tolist() == [0, 255, 0]  # on the line, away from the sky tick
    assert np.all(out[100, 100] == 100) and np.all(out[300, 100] == 100)  # off the line
    # The sky tick at the middle of the segment points up, not down.
    assert out[195, 320, 1] == 255 and np.all(out[205, 320] != [0, 255, 0])


def test_draw_horizon_writes_the_fov_note():
    up_c = np.array([0.0, -1.0, 0.0])
    plain = draw_horizon(grey_image(), up_c, K)
    noted = draw_horizon(grey_image(), up_c, K, fov_note=assumed_fov_note())
    changed = np.any(noted != plain, axis=2)
    rows, cols = np.nonzero(changed)
    assert changed.sum() > 200
    assert rows.min() > H * 0.85 and cols.max() < W * 0.5  # bottom-left corner only


def test_draw_horizon_out_of_view_draws_no_line():
    out = draw_horizon(grey_image(), np.array([0.0, 0.0, -1.0]), K)
    assert np.all(out[H // 2 :] == 100)  # only the note at the top changed anything
    assert np.any(out[:40] != 100)


def test_draw_manhattan_axes_colours_each_axis_and_the_vanishing_point():
    rgb = grey_image()
    K_c = assumed_K(H, W)
    out = draw_manhattan_axes(rgb, np.eye(3), K_c)
    assert out.shape == rgb.shape and out.dtype == np.uint8 and np.all(rgb == 100)
    cx, cy = 320, 240  # the pixel nearest the image centre (319.5, 239.5)
    assert out[cy, cx + 30].tolist() == [255, 0, 0]  # X: right
    assert out[cy + 30, cx].tolist() == [0, 255, 0]  # Y: down
    radius = 4 * 2  # 4 x the stroke (2 px at 480 rows)
    assert out[cy - radius, cx].tolist() == [0, 0, 255]  # Z's vanishing point: a blue ring at the centre
    assert np.all(out[cy - 60, cx - 60] == 100)


def test_draw_overlay_notes_an_assumed_fov_only():
    up_c = np.array([0.0, -1.0, 0.0])
    K_60 = assumed_K(H, W, 60.0)
    with_K = draw_overlay(grey_image(), up_c, np.eye(3), K_60)
    assumed = draw_overlay(grey_image(), up_c, np.eye(3), None, fov_deg=60.0)
    assert np.array_equal(with_K, draw_manhattan_axes(draw_horizon(grey_image(), up_c, K_60), np.eye(3), K_60))
    with_note = draw_horizon(grey_image(), up_c, K_60, assumed_fov_note(60.0))
    assert np.array_equal(assumed, draw_manhattan_axes(with_note, np.eye(3), K_60))
    assert np.array_equal(draw_overlay(grey_image(), up_c), draw_horizon(grey_image(), up_c, K_60, assumed_fov_note()))


def test_drawing_rejects_non_uint8_rgb():
    with pytest.raises(InputError, match="uint8"):
        draw_horizon(np.zeros((H, W, 3), np.float32), np.array([0.0, -1.0, 0.0]), K)
    with pytest.raises(InputError, match=r"\(H, W, 3\)"):
        draw_manhattan_axes(np.zeros((H, W), np.uint8), np.eye(3), K)


def test_draw_ground_blends_the_colour_and_resizes_a_low_resolution_mask():
    rgb = np.zeros((4, 6, 3), np.uint8)
    mask = np.zeros((2, 3), bool)
    mask[1] = True  # bottom half
    out = draw_ground(rgb, mask, colour_rgb=(0, 200, 0), alpha=0.5)
    assert out.shape == rgb.shape and out.dtype == np.uint8
    assert np.all(out[2:] == [0, 100, 0]) and np.all(out[:2] == 0)
    weighted = draw_ground(np.full((2, 2, 3), 100, np.uint8), np.array([[0.0, 0.5], [1.0, 0.0]]), (200, 200, 200), 1.0)
    assert weighted[:, :, 0].tolist() == [[100, 150], [200, 100]]
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        draw_ground(rgb, np.full((4, 6), 2.0))


# ---------------------------------------------------------------- panes


def test_side_by_side_panes_normals_and_confidence():
    rgb = grey_image(120, 160)
    normals = np.zeros((60, 80, 3), np.float32)
    normals[..., 2] = -1.0  # facing the camera
    kappa = np.full((60, 80), 75.0, np.float32)
    kappa[30:] = 37.5
    out = side_by_side(rgb, NormalMap(normals, kappa), include_normals=True, include_confidence=True)
    assert out.shape == (120, 480, 3) and out.dtype == np.uint8
    assert np.array_equal(out[:, :160], rgb)
    assert out[100, 160 + 80].tolist() == normals_to_rgb(normals)[50, 40].tolist() == [128, 128, 0]
    assert out[50, 320 + 80].tolist() == [255, 255, 255]  # kappa at the cap 75: white
    assert out[100, 320 + 80].tolist() == [128, 128, 128]  # half the cap: mid grey

    only_conf = side_by_side(rgb, NormalMap(normals, kappa), include_normals=False, include_confidence=True)
    assert only_conf.shape == (120, 320, 3) and only_conf[50, 240].tolist() == [255, 255, 255]
    missing = side_by_side(rgb, None, include_normals=True, include_confidence=True)
    assert missing.shape == (120, 480, 3) and np.all(missing[60:, 160:] == 0)
