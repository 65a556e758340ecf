"""A stream's steady normals-to-segments offset (`solver/cue_offset.py`): a steady offset times shares that change
from frame to frame is not let through as frame-to-frame error; cues that agree, or one cue, move nothing."""

import numpy as np
import pytest

from uareme_fusion.rotations import exp_so3, log_so3
from uareme_fusion.solver.cue_offset import CueOffset
from uareme_fusion.types import VisualRotation


def _joint_frame(R_normals, d_lines_from_normals, lam, jump_deg=0.0) -> VisualRotation:
    """The joint rotation at fraction `lam` from the normals' own minimum to the segments' own, with both
    cues' own minima as offsets from it (as `JointSolver.solve` reports them)."""
    R_joint = R_normals @ exp_so3(lam * d_lines_from_normals)
    cues = {"normals": {"own_offset_rad": -lam * d_lines_from_normals},
            "lines": {"own_offset_rad": (1.0 - lam) * d_lines_from_normals}}
    return VisualRotation(R_cm=R_joint, cov=np.eye(3) * 1e-4, cost=0.1, iterations=1, n_valid=100, cues=cues,
                          jump_deg=jump_deg)


def _angle_deg(R_a, R_b) -> float:
    return float(np.degrees(np.linalg.norm(log_so3(R_a.T @ R_b))))


def test_a_steady_offset_with_changing_shares_does_not_become_frame_to_frame_error():
    rng = np.random.default_rng(0)
    R_true = exp_so3([0.1, -0.2, 0.3])
    d = np.radians([6.0, -6.0, 8.0])  # 11.7 deg steady, as EuRoC V1_01 micro's cues
    tracker, raw, corrected = CueOffset(), [], []
    for _ in range(60):
        R_normals = R_true @ exp_so3(rng.normal(scale=np.radians(0.3), size=3))
        d_k = d + rng.normal(scale=np.radians(0.3), size=3)
        frame = _joint_frame(R_normals, d_k, lam=float(np.clip(rng.normal(0.72, 0.16), 0.05, 0.95)))
        raw.append(frame.R_cm)
        corrected.append(tracker.update(frame).R_cm)
    reference = R_true @ exp_so3(0.72 * d)  # the steady mixture
    raw_err = np.mean([_angle_deg(R, reference) for R in raw[10:]])
    corrected_err = np.mean([_angle_deg(R, reference) for R in corrected[10:]])
    assert raw_err > 1.4, raw_err  # 0.16 x 11.7 deg of share jitter
    assert corrected_err < 0.8 and corrected_err < raw_err / 2.5  # left: the cues' own 0.3 deg per axis


def test_cues_that_agree_or_a_single_cue_move_nothing():
    rng = np.random.default_rng(1)
    tracker = CueOffset()
    for _ in range(40):
        R = exp_so3(rng.normal(scale=0.3, size=3))
        frame = _joint_frame(R, rng.normal(scale=np.radians(1.0), size=3), lam=float(rng.uniform(0.2, 0.8)))
        assert _angle_deg(tracker.update(frame).R_cm, frame.R_cm) < 0.15  # zero-mean offsets: no steady part
    alone = VisualRotation(R_cm=np.eye(3), cov=np.eye(3), cost=0.1, iterations=1, n_valid=10,
                           cues={"lines": {"share": 1.0}})
    assert tracker.update(alone) is alone


def test_a_jump_starts_the_means_again():
    tracker = CueOffset()
    d = np.radians([0.0, 0.0, 10.0])
    for lam in (0.3, 0.7, 0.5, 0.4, 0.6):
        tracker.update(_joint_frame(np.eye(3), d, lam))
    assert tracker.offset() is not None
    tracker.update(_joint_frame(np.eye(3), d, 0.5, jump_deg=30.0))
    assert tracker.frames == 1 and tracker.offset() is None


def test_a_network_map_explained_badly_counts_fewer_independent_errors():
    """`NormalMap.regions_cost` (`manhattan.surface_regions`): above it the covariance grows as the residual
    itself, in the normals-only and in the joint solver alike; below it, and without it, nothing changes."""
    import dataclasses

    from uareme_fusion.sim.normal_maps import manhattan_normal_map
    from uareme_fusion.solver import solve_manhattan
    from uareme_fusion.solver.joint import JointSolver
    from uareme_fusion.solver.manhattan import surface_regions

    assert surface_regions(3.0, 0.01, 0.03) == 3.0 and surface_regions(3.0, 0.5, None) == 3.0
    assert surface_regions(3.0, 0.09, 0.03) == pytest.approx(1.0)
    rng = np.random.default_rng(2)
    R_true = exp_so3([0.2, -0.1, 0.4])
    for noise_deg, widened in ((4.0, False), (12.0, True)):
        plain = manhattan_normal_map(R_true, rng, height=48, width=64, noise_deg=noise_deg)
        plain = dataclasses.replace(plain, independent_regions=3.0)
        network = dataclasses.replace(plain, regions_cost=0.03)
        a, b = solve_manhattan(plain), solve_manhattan(network)
        np.testing.assert_allclose(a.R_cm, b.R_cm)
        ratio = np.trace(b.cov) / np.trace(a.cov)
        if widened:
            assert a.cost > 0.03 and ratio == pytest.approx(a.cost / 0.03, rel=0.05)
        else:
            assert a.cost < 0.03 and ratio == pytest.approx(1.0)
    lines_free = JointSolver()._normal_cue(network)  # the joint's normal cue: a_N shrinks the same way
    lines_free.set_alpha(b.R_cm)
    plain_cue = JointSolver()._normal_cue(plain)
    plain_cue.set_alpha(b.R_cm)
    assert lines_free.alpha == pytest.approx(plain_cue.alpha * 0.03 / a.cost, rel=1e-6)
