"""The camera's rotation between frames from the image motion (`solver/frame_motion.py`) on a texture seen
by a camera turned about its centre (exact homographies), and what it hands the stream
(`VisualRotation.R_cp` through `CueSolver`)."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.solver.cues import CueSolver
from uareme_fusion.rotations import angle_between
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.sim.render import intrinsics_from_fov
from uareme_fusion.solver.frame_motion import FrameMotion, FrameMotionConfig
from uareme_fusion.types import Frame

W, H = 320, 240


def _textured(seed: int = 0) -> np.ndarray:
    """A seeded texture (blurred noise at two scales), RGB uint8 H x W."""
    rng = np.random.default_rng(seed)
    coarse = cv2.resize(rng.uniform(0, 255, (H // 8, W // 8, 3)).astype(np.float32), (W, H))
    fine = cv2.GaussianBlur(rng.uniform(0, 255, (H, W, 3)).astype(np.float32), (0, 0), 1.5)
    return np.clip(0.6 * coarse + 0.4 * fine, 0, 255).astype(np.uint8)


def _turned(rgb: np.ndarray, K: np.ndarray, R_cp: np.ndarray) -> np.ndarray:
    """The view of a camera turned by R_cp (previous camera -> this one) about its centre: the image
    warped by the homography K R_cp K^-1 (exact for a rotation)."""
    return cv2.warpPerspective(rgb, K @ R_cp @ np.linalg.inv(K), (W, H), flags=cv2.INTER_LINEAR)


@pytest.fixture(scope="module")
def room():
    return _textured(), intrinsics_from_fov(W, H, 65.0)


@pytest.mark.parametrize("turn_deg", [(0.0, 0.0, 0.0), (2.0, -1.0, 0.5), (0.0, 4.0, 0.0), (3.0, 0.0, 3.0)])
def test_rotation_between_two_views_is_the_cameras(room, turn_deg):
    image, K = room
    R_cp = Rotation.from_euler("xyz", turn_deg, degrees=True).as_matrix()
    motion = FrameMotion()
    assert motion.step(0.0, image, K) is None  # the first frame has no previous one
    step = motion.step(1 / 30, _turned(image, K, R_cp), K)
    assert step is not None and step.inliers >= FrameMotionConfig().min_inliers
    assert np.degrees(angle_between(step.R_cp, R_cp)) < 0.3  # (0.24 with 3 deg of roll)
    assert FrameMotionConfig().std_base_rad <= step.std_rad < np.radians(0.5)  # exact views: little residual


def test_no_rotation_from_a_blank_frame_a_gap_or_another_camera(room):
    view, K = room
    motion = FrameMotion()
    motion.step(0.0, view, K)
    assert motion.step(0.033, np.full_like(view, 128), K) is None  # nothing to track
    motion.step(1.0, view, K)
    assert motion.step(2.0, view, K) is None  # a second apart: not tracked across
    assert motion.step(2.03, view, K * np.array([[1.1], [1.1], [1.0]])) is None  # other intrinsics
    assert motion.step(2.06, view, None) is None


def test_cue_solver_hands_the_image_rotation_to_the_stream(room):
    image, K = room
    R_cp = Rotation.from_euler("y", 3.0, degrees=True).as_matrix()
    R_pm = Rotation.from_euler("xyz", [10.0, 25.0, -5.0], degrees=True).as_matrix()
    rng = np.random.default_rng(1)
    maps = [manhattan_normal_map(R, rng, noise_deg=3.0) for R in (R_pm, R_cp @ R_pm)]
    cues, plain = CueSolver(lines=False), CueSolver(lines=False, motion=False)
    out = [cues.solve(Frame(k / 30, rgb=rgb, K=K, index=k), nm)
           for k, (rgb, nm) in enumerate(zip((image, _turned(image, K, R_cp)), maps))]
    assert out[0].R_cp is None and np.isnan(out[0].R_cp_std_rad)
    assert np.degrees(angle_between(out[1].R_cp, R_cp)) < 0.1
    R_cm_moved = out[1].R_cp @ out[0].R_cm  # R_cm = R_cp R_pm: the image rotation and the solves agree
    assert np.degrees(angle_between(out[1].symmetric_to(R_cm_moved).R_cm, R_cm_moved)) < 1.0
    assert plain.solve(Frame(0.0, rgb=image, K=K, index=0), maps[0]).R_cp is None


def test_a_K_from_the_scene_widens_the_std_by_its_factor_not_the_rotation(room):
    """The std model: `std_base + std_per_step |step| + std_per_residual rms`, times `scene_K_std_scale`
    when the K was estimated from the scene; the rotation itself is the same."""
    image, K = room
    R_cp = Rotation.from_euler("xyz", (2.0, -1.0, 0.5), degrees=True).as_matrix()
    views = (image, _turned(image, K, R_cp))
    steps = {}
    for from_scene in (False, True):
        motion = FrameMotion()
        motion.step(0.0, views[0], K, K_from_scene=from_scene)
        steps[from_scene] = motion.step(1 / 30, views[1], K, K_from_scene=from_scene)
    given, scene = steps[False], steps[True]
    cfg = FrameMotionConfig()
    assert cfg.scene_K_std_scale == 3.0
    np.testing.assert_allclose(scene.R_cp, given.R_cp, atol=1e-12)
    assert scene.std_rad == pytest.approx(cfg.scene_K_std_scale * given.std_rad, rel=1e-12)
    step_rad = Rotation.from_matrix(given.R_cp).magnitude()
    assert given.std_rad >= cfg.std_base_rad + cfg.std_per_step * step_rad  # plus the residual's share
    assert given.std_rad < cfg.std_base_rad + cfg.std_per_step * step_rad + np.radians(0.3)
    scaled = FrameMotion(FrameMotionConfig(scene_K_std_scale=1.5))
    scaled.step(0.0, views[0], K, K_from_scene=True)
    assert scaled.step(1 / 30, views[1], K, K_from_scene=True).std_rad == pytest.approx(1.5 * given.std_rad, rel=1e-12)


def test_cue_solver_widens_the_image_rotation_of_a_K_it_estimated(room):
    """A frame without K (the stream's K estimated from the scene) hands a std `scene_K_std_scale` times
    that of the same frames with that K given."""
    from uareme_fusion.solver.focal import FocalEstimate

    image, K = room
    R_cp = Rotation.from_euler("y", 3.0, degrees=True).as_matrix()
    R_pm = Rotation.from_euler("xyz", [10.0, 25.0, -5.0], degrees=True).as_matrix()
    normals = manhattan_normal_map(R_pm, np.random.default_rng(1), noise_deg=3.0)
    stds = {}
    for given in (True, False):
        cues = CueSolver(lines=False)
        cues.focal = FocalEstimate(K, "estimated", width=W)  # as the stream's K pooled from the scene
        solved = CueSolver(lines=False, motion=False).solve(Frame(0.0, rgb=image, K=K, index=0), normals)
        for k, rgb in enumerate((image, _turned(image, K, R_cp))):
            out = cues._with_motion(Frame(k / 30, rgb=rgb, K=K if given else None, index=k), solved)
        stds[given] = out.R_cp_std_rad
    assert np.isfinite(stds[True])
    assert stds[False] == pytest.approx(FrameMotionConfig().scene_K_std_scale * stds[True], rel=1e-9)
