"""The steady part of a covariance (a calibration error shared by a stream's frames) and the NEES after the
constant alignment, which scores what the alignment leaves of it (`metrics.aligned_covariance`)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.backends.base import SteadyPart
from uareme_fusion.rotations import exp_so3
from uareme_fusion.scoring.metrics import aligned_covariance, attitude_errors, view_overlap
from uareme_fusion.types import Estimate, Status, VisualRotation, steady_within


def _stream(n, turn_deg, steady_std_rad, frame_std_rad, seed=0):
    """n camera rotations turning `turn_deg` about world z in all, each wrong by one shared camera-fixed
    error (std `steady_std_rad` per axis) and its own (`frame_std_rad`)."""
    rng = np.random.default_rng(seed)
    yaw = np.radians(np.linspace(0.0, turn_deg, n))
    R_true = Rotation.from_euler("z", yaw[:, None]).as_matrix() @ Rotation.from_euler("x", -90, degrees=True).as_matrix()
    bias = rng.normal(0.0, steady_std_rad, 3)
    R_est = np.array([R @ exp_so3(-(bias + rng.normal(0.0, frame_std_rad, 3))) for R in R_true])
    cov = np.broadcast_to((steady_std_rad**2 + frame_std_rad**2) * np.eye(3), (n, 3, 3)).copy()
    steady = np.broadcast_to(steady_std_rad**2 * np.eye(3), (n, 3, 3)).copy()
    return R_est, R_true, cov, steady


def _mean_nees(R_est, R_true, cov, steady=None):
    return float(np.nanmean(attitude_errors(R_est, cov, np.ones(len(R_est), bool), R_true,
                                            cov_steady_rad2=steady)["nees"]))


def test_a_still_camera_is_scored_against_its_per_frame_part():
    runs = [_stream(200, 0.0, np.radians(2.0), np.radians(0.2), seed) for seed in range(20)]
    whole = np.mean([_mean_nees(*r[:3]) for r in runs])
    split = np.mean([_mean_nees(*r) for r in runs])
    assert whole < 0.1  # the steady 2 deg is gone after the alignment: the whole covariance claims it
    assert split == pytest.approx(3.0, rel=0.1)


def test_a_camera_turning_through_unrelated_views_keeps_the_steady_part():
    runs = [_stream(200, 360.0, np.radians(2.0), np.radians(0.2), seed) for seed in range(40)]
    split = np.mean([_mean_nees(*r) for r in runs])
    assert 1.5 < split < 4.5  # most of the shared error stays: scored near the whole covariance


def test_aligned_covariance_of_a_fully_shared_error_is_the_alignment_residual():
    _, R_wc, cov, steady = _stream(5, 0.0, 0.02, 0.001)
    np.testing.assert_allclose(view_overlap(R_wc), 1.0)
    np.testing.assert_allclose(aligned_covariance(R_wc, cov, steady), cov - steady, atol=1e-12)  # all of it goes
    _, R_wc, cov, steady = _stream(4, 270.0, 0.02, 0.001)  # views 90 deg apart share nothing
    L = 0.02 * np.eye(3)
    M = R_wc @ L
    expected = [cov[k] - steady[k] + L @ L.T - (R_wc[k].T @ M[k] @ L.T + L @ M[k].T @ R_wc[k]) / 4
                + R_wc[k].T @ sum(m @ m.T for m in M) @ R_wc[k] / 16 for k in range(4)]
    np.testing.assert_allclose(aligned_covariance(R_wc, cov, steady), expected, atol=1e-12)


def test_view_overlap_falls_with_the_angle_between_optical_axes():
    R = Rotation.from_euler("y", [[0.0], [30.0], [60.0], [90.0]], degrees=True).as_matrix()
    np.testing.assert_allclose(view_overlap(R)[0], [1.0, 0.5, 0.0, 0.0], atol=1e-9)  # 1 - 3 t^2 + 2 t^3


def test_steady_within_keeps_the_steady_part_inside_the_covariance():
    cov = np.diag([1e-4, 4e-4, 9e-4])
    np.testing.assert_allclose(steady_within(cov, 1e-4 * np.eye(3)), 1e-4 * np.eye(3), atol=1e-15)
    shrunk = steady_within(cov, 5e-4 * np.eye(3))
    assert np.linalg.eigvalsh(cov - shrunk).min() > -1e-15
    np.testing.assert_allclose(np.diag(shrunk), [1e-4, 4e-4, 5e-4], atol=1e-15)
    assert steady_within(cov, None) is None


def test_the_steady_part_follows_a_relabelling_and_reaches_the_estimate():
    R_cm = Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix()
    steady = np.diag([1e-4, 2e-4, 3e-4])
    visual = VisualRotation(R_cm, steady + 1e-6 * np.eye(3), 0.0, 1, 1, cov_steady=steady)
    P = Rotation.from_euler("z", 90, degrees=True).as_matrix().round()
    moved = visual.symmetric_to(R_cm @ P)
    np.testing.assert_allclose(moved.cov_frame(), 1e-6 * np.eye(3), atol=1e-15)
    carry = SteadyPart()
    est = carry(Estimate(0.0, R_cm.T, 2e-4 * np.eye(3)), moved)
    assert np.linalg.eigvalsh(est.cov - est.cov_steady).min() > -1e-15  # within the estimate's covariance
    assert carry(Estimate(1.0, np.eye(3), np.eye(3), Status.NOT_INITIALISED), None).cov_steady is None
    assert carry(Estimate(2.0, R_cm.T, np.eye(3)), None).cov_steady is not None  # a missing frame keeps it


def test_a_long_run_takes_the_alignment_mean_from_a_subset_of_frames(monkeypatch):
    from uareme_fusion.scoring import metrics

    R_wc = Rotation.random(600, random_state=3).as_matrix()
    cov = np.broadcast_to(2e-4 * np.eye(3), (600, 3, 3)).copy()
    whole = aligned_covariance(R_wc, cov, 0.5 * cov)
    monkeypatch.setattr(metrics, "_MEAN_FRAMES", 100)
    np.testing.assert_allclose(aligned_covariance(R_wc, cov, 0.5 * cov), whole, atol=1e-5)  # 5 % of the variances
