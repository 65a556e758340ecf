"""Issue 29 (solver side): a cue without information cannot choose or steer, a stream's prior is a start and
not an anchor, a frame without evidence reports a wide covariance and why."""

import numpy as np
import pytest

from uareme_fusion.solver.line_detection import LineSegments
from uareme_fusion.overlay.camera import assumed_K
from uareme_fusion.solver.cues import CueSolver
from uareme_fusion.rotations import exp_so3, log_so3, nearest_symmetric
from uareme_fusion.sim.line_segments import manhattan_segments
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.solver.evidence import NO_EVIDENCE_TEXTURED_FRACTION, textured_fraction
from uareme_fusion.solver.focal import segment_moments
from uareme_fusion.solver.joint import JointSolver
from uareme_fusion.types import Frame, NormalMap

W, H = 640, 480
K = assumed_K(H, W, 60.0)


def _error_deg(R_est, R_true) -> float:
    R_sym, _ = nearest_symmetric(R_est, R_true)
    return float(np.degrees(np.linalg.norm(log_so3(R_sym.T @ R_true))))


def _clutter_segments(n: int, rng: np.random.Generator) -> LineSegments:
    """n segments in random image directions (no Manhattan structure: no information)."""
    start = rng.uniform([40, 40], [W - 40, H - 40], size=(n, 2))
    theta = rng.uniform(0, np.pi, n)
    end = start + rng.uniform(30, 90, n)[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    ends = np.stack([start, end], axis=1)
    return LineSegments(ends, np.linalg.norm(end - start, axis=1) / np.hypot(W, H), H, W)


def test_segments_without_information_neither_choose_nor_steer():
    errors_joint, errors_normals = [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        R_true = exp_so3(rng.normal(scale=0.4, size=3))
        nm = manhattan_normal_map(R_true, rng, height=48, width=64, noise_deg=12.0)
        nm = NormalMap(nm.normals, nm.kappa, independent_regions=60.0)  # a real sensor's weight
        lines = segment_moments(_clutter_segments(60, rng), K)
        joint = JointSolver().solve(nm, lines)
        errors_joint.append(_error_deg(joint.R_cm, R_true))
        errors_normals.append(_error_deg(JointSolver().solve(nm, None).R_cm, R_true))
        assert joint.cues["lines"]["share"] < 0.05
    # The clutter changes the answer by less than a tenth of a degree: no flip, no pull.
    assert np.max(np.abs(np.array(errors_joint) - np.array(errors_normals))) < 0.1
    assert max(errors_joint) < 1.0


def _rotating_stream(seed: int, frames: int = 45, rate_deg_s: float = 100.0, fps: float = 30.0):
    rng = np.random.default_rng(seed)
    axis = np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5])
    R0 = exp_so3([0.2, 0.3, 0.1])
    for k in range(frames):
        R_true = exp_so3(axis * np.radians(rate_deg_s) * k / fps) @ R0
        seg = manhattan_segments(R_true, K, W, H, per_axis=(12, 12, 12), noise_px=0.7, clutter=6, rng=rng)
        nm = manhattan_normal_map(R_true, rng, height=48, width=64, noise_deg=20.0)
        yield R_true, nm, segment_moments(seg, K)


@pytest.mark.parametrize("cues", ["lines", "both"])
def test_a_stream_turning_100_deg_per_s_is_followed(cues):
    solver, R_prev, errors = JointSolver(), None, []
    for R_true, nm, lines in _rotating_stream(1):
        visual = solver.solve(nm if cues == "both" else None, lines, R_prev)
        R_prev = visual.R_cm
        errors.append(_error_deg(visual.R_cm, R_true))
    assert max(errors) < 2.0  # 45 frames, 150 deg turned, every frame within 2 deg


def test_a_wrong_prior_is_a_start_not_an_anchor_and_the_jump_is_flagged():
    rng = np.random.default_rng(3)
    R_true = exp_so3([0.1, 0.5, 0.05])
    wrong = R_true @ exp_so3([0.0, np.radians(35.0), 0.0])  # e.g. the last frame, before a fast turn
    seg = manhattan_segments(R_true, K, W, H, per_axis=(12, 12, 12), noise_px=0.7, clutter=4, rng=rng)
    box = manhattan_segments(wrong, K, W, H, per_axis=(5, 5, 5), noise_px=0.7, rng=rng)  # a box at the old angle
    ends = np.concatenate([seg.endpoints_px, box.endpoints_px])
    lines = segment_moments(LineSegments(ends, np.concatenate([seg.weights, box.weights]), H, W), K)
    nm = manhattan_normal_map(R_true, rng, height=48, width=64, noise_deg=15.0)
    visual = JointSolver().solve(None, lines, R_init=wrong)
    assert _error_deg(visual.R_cm, R_true) < 1.0
    assert visual.jump_deg > 20.0
    kept = JointSolver().solve(nm, lines, R_init=R_true @ exp_so3([0.0, 0.02, 0.0]))
    assert kept.jump_deg == 0.0 and _error_deg(kept.R_cm, R_true) < 1.0


@pytest.mark.parametrize("image", ["black", "blank", "blurred"])
def test_a_frame_without_evidence_gets_the_capped_covariance_and_says_why(image):
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, size=(H, W, 3)).astype(np.uint8)
    rgb = {"black": np.zeros((H, W, 3), np.uint8), "blank": np.full((H, W, 3), 128, np.uint8),
           "blurred": np.full((H, W, 3), 128, np.uint8) + (base // 64).astype(np.uint8)}[image]
    assert textured_fraction(rgb) < NO_EVIDENCE_TEXTURED_FRACTION
    # A network's confident guess of an upright room on that frame:
    nm = manhattan_normal_map(np.eye(3), rng, height=48, width=64, noise_deg=3.0)
    visual = CueSolver().solve(Frame(0.0, rgb=rgb, K=K), nm)
    assert np.degrees(np.sqrt(np.linalg.eigvalsh(visual.cov).min())) > 50.0
    assert "no image evidence" in visual.reason
    depth_visual = CueSolver(image_normals=False).solve(Frame(0.0, rgb=rgb, K=K), nm)
    assert depth_visual.reason == "" and np.degrees(np.sqrt(np.linalg.eigvalsh(depth_visual.cov).max())) < 5.0


def test_a_grey_one_channel_frame_is_judged_and_solved():
    rng = np.random.default_rng(2)
    R_true = exp_so3([0.05, 0.4, 0.02])
    seg = manhattan_segments(R_true, K, W, H, per_axis=(12, 12, 12), noise_px=0.5, rng=rng)
    grey = np.zeros((H, W), np.uint8)
    import cv2

    for (x1, y1), (x2, y2) in seg.endpoints_px:
        cv2.line(grey, (int(x1), int(y1)), (int(x2), int(y2)), 255, 2)
    assert textured_fraction(grey) > NO_EVIDENCE_TEXTURED_FRACTION
    visual = CueSolver().solve(Frame(0.0, rgb=grey, K=K), None)
    assert visual is not None and visual.reason == "" and _error_deg(visual.R_cm, R_true) < 1.5
