"""The robust line cue (Cauchy reweighting of the sextic, `solver/joint.py`) and the RGB-only backend
comparison's reference (`benchmarks/horizon.chained_reference`)."""

import numpy as np

from uareme_fusion.benchmarks.horizon import chained_reference
from uareme_fusion.solver.line_detection import LineSegments
from uareme_fusion.overlay.camera import assumed_K
from uareme_fusion.rotations import exp_so3, log_so3, manhattan_symmetries, nearest_symmetric
from uareme_fusion.sim.line_segments import manhattan_segments
from uareme_fusion.solver.focal import segment_moments
from uareme_fusion.solver.joint import JointSolver, LineCueConfig

W, H = 640, 480
N_AIMED = 8


def _error_deg(R_est, R_true) -> float:
    R_sym, _ = nearest_symmetric(R_est, R_true)
    return float(np.degrees(np.linalg.norm(log_so3(R_sym.T @ R_true))))


def _aimed_at_centre(n: int, rng: np.random.Generator) -> np.ndarray:
    """End points (n, 2, 2) of segments whose lines pass within 3 px of the image centre (clutter that
    the plain sextic reads as lines along an optical-axis Manhattan axis)."""
    theta = rng.uniform(0, np.pi, n)
    u = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    start = rng.uniform(60, 200, n)[:, None] * u + rng.normal(scale=3.0, size=(n, 2))
    length = rng.uniform(30, 80, n)[:, None]
    return np.array([W / 2 - 0.5, H / 2 - 0.5]) + np.stack([start, start + length * u], axis=1)


def _corridor_scene(seed: int):
    """A yawed Manhattan frame seen through 10 segments per axis, plus 12 segments aimed at the centre."""
    rng = np.random.default_rng(seed)
    K = assumed_K(H, W, 60.0)
    R_true = exp_so3([0.05, 0.6, 0.03])
    seg = manhattan_segments(R_true, K, W, H, per_axis=(15, 15, 15), noise_px=0.7, rng=rng)
    ends = np.concatenate([seg.endpoints_px, _aimed_at_centre(N_AIMED, rng)])
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    return LineSegments(ends, length / np.hypot(W, H), H, W), K, R_true


def test_reweighting_keeps_the_frame_that_clutter_aimed_at_the_centre_pulls_away():
    robust, plain = [], []
    for seed in range(4):
        seg, K, R_true = _corridor_scene(seed)
        lines = segment_moments(seg, K)
        robust.append(_error_deg(JointSolver().solve(None, lines).R_cm, R_true))
        plain.append(_error_deg(JointSolver(line_config=LineCueConfig(robust_iterations=0)).solve(None, lines).R_cm,
                                R_true))
    assert max(robust) < 1.0
    assert np.mean(plain) > 2.0 * np.mean(robust)  # the plain sextic is biased on the same segments


def test_a_good_prior_is_kept_not_slid_away_from():
    for seed in range(3):
        seg, K, R_true = _corridor_scene(seed)
        visual = JointSolver().solve(None, segment_moments(seg, K), R_init=R_true @ exp_so3([0.0, 0.02, 0.0]))
        assert _error_deg(visual.R_cm, R_true) < 1.0


def test_chained_reference_undoes_per_frame_symmetry_choices():
    rng = np.random.default_rng(4)
    R_cm = [exp_so3([0.1, 0.2 + 0.01 * k, 0.0]) for k in range(20)]
    symmetries = manhattan_symmetries()
    relabelled = [R @ symmetries[rng.integers(len(symmetries))] for R in R_cm]
    R_wc = chained_reference(relabelled)
    steps = [np.degrees(np.linalg.norm(log_so3(R_wc[k - 1] @ R_wc[k].T))) for k in range(1, len(R_wc))]
    assert max(steps) < 1.0
    np.testing.assert_allclose(R_wc[0], relabelled[0].T, atol=1e-12)
