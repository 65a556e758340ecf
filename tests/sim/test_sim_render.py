"""Renderer: normals agree with depth, Manhattan mask, scenes are seeded."""

import numpy as np
import pytest

from uareme_fusion.errors import InputError
from uareme_fusion.sim.render import Renderer, intrinsics_from_fov
from uareme_fusion.sim.scenarios import build_scenario
from uareme_fusion.sim.scenes import SCENE_NAMES, make_scene


def _points(depth, K):
    H, W = depth.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1) * depth[..., None]


def _fd_normals(depth, K):
    """Normals from central differences of the back-projected depth, facing the camera."""
    P = _points(depth, K)
    du = P[1:-1, 2:] - P[1:-1, :-2]
    dv = P[2:, 1:-1] - P[:-2, 1:-1]
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=-1, keepdims=True) + 1e-300
    n *= -np.sign(np.sum(n * P[1:-1, 1:-1], axis=-1, keepdims=True))
    return n


def _planar_interior(normals, depth, K):
    """Pixels whose 3x3 neighbourhood has depth, the same rendered normal and the same plane
    offset n . P within 1 mm (one plane, not a poster 2 cm in front of its wall)."""
    ok = depth > 0
    same = np.ones(depth.shape, bool)
    offset = np.sum(normals * _points(depth, K), -1)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            shift = lambda a: np.roll(np.roll(a, dy, 0), dx, 1)  # noqa: E731
            same &= (np.sum(shift(normals) * normals, -1) > 1 - 1e-6) & (np.abs(shift(offset) - offset) < 1e-3)
            ok &= shift(depth > 0)
    return (same & ok)[1:-1, 1:-1]


@pytest.mark.parametrize("scenario", ["room", "office", "bus"])
def test_rendered_normals_match_finite_difference_normals_within_1_degree(scenario):
    world = build_scenario(scenario, 6.0, seed=2)
    K = intrinsics_from_fov(160, 120, 70.0)
    renderer = Renderer(world.scene, K, 160, 120)
    for t in (0.0, 2.5, 5.0):
        _, depth, normals_c, _, _, _ = world.render_radiance(renderer, t)
        planar = _planar_interior(normals_c, depth, K)
        assert planar.mean() > 0.5
        angle = np.degrees(np.arccos(np.clip(np.sum(_fd_normals(depth, K) * normals_c[1:-1, 1:-1], -1), -1, 1)))
        assert angle[planar].max() < 1.0


def test_normals_are_unit_face_the_camera_and_mask_marks_axis_aligned_pixels():
    world = build_scenario("room", 4.0, seed=0)
    K = intrinsics_from_fov(160, 120, 60.0)
    renderer = Renderer(world.scene, K, 160, 120)
    _, depth, n_c, mask, R_wc, _ = world.render_radiance(renderer, 1.0)
    hit = depth > 0
    np.testing.assert_allclose(np.linalg.norm(n_c[hit], axis=-1), 1.0, atol=1e-5)
    v, u = np.mgrid[0:120, 0:160]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(u.shape)], -1)
    assert np.all(np.sum(rays * n_c, -1)[hit] < 0)  # facing the camera
    n_w = n_c[hit] @ R_wc.T
    aligned = np.abs(n_w).max(axis=-1) >= np.cos(np.radians(1.0))
    np.testing.assert_array_equal(mask[hit], aligned)
    assert 0.6 < mask.mean() <= 1.0


def test_bus_interior_is_manhattan_in_the_moving_body_frame():
    world = build_scenario("bus", 30.0, seed=1)
    K = intrinsics_from_fov(120, 90, 90.0)
    renderer = Renderer(world.scene, K, 120, 90)
    for t in (5.0, 20.0):
        _, depth, n_c, mask, R_wc, _ = world.render_radiance(renderer, t)
        R_wm = world.trajectory.R_wm(t)[0]
        n_m = n_c[mask] @ (R_wc.T @ R_wm)  # rows: normals in the Manhattan (bus) frame
        assert mask.mean() > 0.5
        assert np.all(np.abs(n_m).max(axis=-1) > np.cos(np.radians(1.0)))


def test_scenes_are_seeded():
    for name in SCENE_NAMES:
        a, b = make_scene(name, 3), make_scene(name, 3)
        np.testing.assert_array_equal(a.textures, b.textures)
        assert a.as_dict() == b.as_dict()
    assert make_scene("room", 3).as_dict() != make_scene("room", 4).as_dict()


def test_sky_and_bad_fov():
    world = build_scenario("street", 4.0, seed=0)
    renderer = Renderer(world.scene, intrinsics_from_fov(80, 60, 90.0), 80, 60)
    R_up = np.eye(3)  # camera z (forward) along world z: looking straight up
    frame = renderer.render(R_up, np.array([0.0, 0.0, 1.5]))
    assert frame.rgb.dtype == np.uint8 and frame.rgb.shape == (60, 80, 3)
    assert (frame.depth == 0).mean() > 0.3  # sky: no depth, zero normals
    assert np.all(frame.normals_c[frame.depth == 0] == 0)
    with pytest.raises(InputError, match="field of view"):
        intrinsics_from_fov(80, 60, 170.0)
