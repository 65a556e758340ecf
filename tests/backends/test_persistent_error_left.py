"""`backends/persistent_error_left.py`: the share of the frames' persistent error that an estimate
averaging them still carries, and its correlation read from the image rotations between frames."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.backends.factory import make_backend
from uareme_fusion.backends.persistent_error_left import PersistentErrorLeft
from uareme_fusion.evaluation.compare import errors_over_time, run_backend
from uareme_fusion.evaluation.sequence import VisualSequence
from uareme_fusion.types import VisualRotation

STD_RAD = np.radians(2.0)


def _frame(R_cm: np.ndarray, R_cp: np.ndarray | None = None, R_cp_std_rad: float = float("nan")) -> VisualRotation:
    return VisualRotation(R_cm, STD_RAD**2 * np.eye(3), 0.0, 1, 1000, R_cp=R_cp, R_cp_std_rad=R_cp_std_rad)


def _fraction_after(phi: float, g: float, steps: int) -> float:
    """`fraction` after `steps` frames fused at gain `g` with the correlation `phi` set by hand."""
    left = PersistentErrorLeft(lag_frames=1000, frames=30)  # never samples: phi stays as set
    left.phi = phi
    for _ in range(steps):
        left.observe(_frame(np.eye(3)), STD_RAD**2 * np.eye(3), fused_trace_rad2=3.0, share=0.05)
        left.settle(g * np.eye(3))  # tr P / tr R = g
    return left.fraction


@pytest.mark.parametrize("g", [0.05, 0.2, 0.7])
def test_an_error_that_never_changes_is_carried_whole_and_a_white_one_as_a_running_average_carries_it(g):
    assert _fraction_after(1.0, g, 300) == pytest.approx(1.0, abs=1e-12)
    assert _fraction_after(0.0, g, 300) == pytest.approx(g / (2.0 - g), rel=1e-9)  # an EWMA of white noise


def test_the_fraction_is_the_variance_of_a_running_average_of_a_gauss_markov_error():
    """Seeded Monte Carlo: eps_k = (1 - g) eps_k-1 + g p_k over p_k = phi p_k-1 + w (Var p = 1)."""
    phi, g, steps, runs = 0.9, 0.2, 120, 20000
    rng = np.random.default_rng(7)
    p = rng.standard_normal(runs)
    eps = p.copy()
    for _ in range(steps - 1):
        p = phi * p + np.sqrt(1.0 - phi * phi) * rng.standard_normal(runs)
        eps = (1.0 - g) * eps + g * p
    predicted = _fraction_after(phi, g, steps - 1)
    assert np.var(eps) == pytest.approx(predicted, rel=0.03)
    assert 0.3 < predicted < 0.8  # neither carried whole nor averaged away


def _stream(phi_true: float, frames: int, seed: int, image_std_rad: float) -> tuple[list[VisualRotation], np.ndarray]:
    """A camera turning 2 deg per frame about a wandering axis, seen through frames whose error (std
    `STD_RAD` per axis, as each frame's covariance says) is a Gauss-Markov process of correlation
    `phi_true` per frame, with image rotations between frames of std `image_std_rad` per axis; and the true
    `R_wc` (N, 3, 3)."""
    rng = np.random.default_rng(seed)
    R_wc, err = np.eye(3), STD_RAD * rng.standard_normal(3)
    out, truth = [], []
    for k in range(frames):
        if k:
            step = Rotation.from_rotvec(np.radians(2.0) * Rotation.random(random_state=rng).apply([1, 0, 0]))
            R_cp_true = step.as_matrix().T  # R_wc,k = R_wc,k-1 R_cp^T
            R_wc = R_wc @ R_cp_true.T
            R_cp = Rotation.from_rotvec(image_std_rad * rng.standard_normal(3)).as_matrix() @ R_cp_true
            err = phi_true * err + np.sqrt(1.0 - phi_true**2) * STD_RAD * rng.standard_normal(3)
        R_mc = R_wc @ Rotation.from_rotvec(err).as_matrix()
        out.append(dataclasses.replace(_frame(R_mc.T, R_cp if k else None, image_std_rad), t_s=k / 30.0))
        truth.append(R_wc)
    return out, np.array(truth)


@pytest.mark.parametrize("phi_true", [0.8, 0.95])
def test_the_correlation_is_read_from_the_image_rotations_net_of_their_drift(phi_true):
    left = PersistentErrorLeft(lag_frames=10, frames=200)
    for v in _stream(phi_true, 1500, seed=3, image_std_rad=np.radians(0.3))[0]:
        left.observe(v, v.cov, fused_trace_rad2=float("nan"), share=0.0)
    assert left.phi == pytest.approx(phi_true, abs=0.02)


def test_a_missing_image_rotation_breaks_the_chain_and_gives_no_sample():
    left = PersistentErrorLeft(lag_frames=3, frames=30)
    frames = _stream(0.0, 20, seed=1, image_std_rad=np.radians(0.3))[0]
    frames = [v if k % 3 else _frame(v.R_cm) for k, v in enumerate(frames)]  # every third without R_cp
    for v in frames:
        left.observe(v, v.cov, fused_trace_rad2=float("nan"), share=0.0)
    assert left.phi == 1.0  # no chain of 3 image rotations: still the conservative start
    left.restart()
    assert left.settle(np.eye(3)) == 1.0  # nothing observed since: unchanged


def _are_nees(name: str, seq: VisualSequence, **overrides) -> tuple[float, float]:
    err = errors_over_time(run_backend(make_backend(name, overrides=overrides), seq), seq.R_wc_true)
    return float(np.nanmean(err["are_deg"])), float(np.nanmean(err["nees"]))


@pytest.mark.slow
def test_the_smoother_reports_what_its_window_leaves_of_a_decorrelating_error():
    """Frames whose error decorrelates within the window (phi 0.9 per frame, about 10 frames), with image
    rotations between them: the paper smoother averages part of it away, and reporting the whole persistent
    share put its NEES under `single`'s; reporting what is left brings it back near `single`'s. Seeded:
    ARE single 2.93 deg, smoother 2.30; NEES single 2.60, smoother 1.94 reporting the whole share, 2.54 now."""
    visuals, R_wc = _stream(0.9, 300, seed=5, image_std_rad=np.radians(0.2))
    seq = VisualSequence("decorrelating", np.array([v.t_s for v in visuals]), visuals, R_wc_true=R_wc)
    single_are, single_nees = _are_nees("single", seq)
    are, nees = _are_nees("smoother", seq)
    whole_are, whole_nees = _are_nees("smoother", seq, visual_persistence_lag_frames=0)
    assert are == pytest.approx(whole_are, abs=1e-9)  # the estimate is the same; only its covariance differs
    assert are < 0.9 * single_are
    assert whole_nees < 0.8 * single_nees
    assert 0.8 * single_nees < nees < 2.0 * single_nees


def test_image_rotations_chain_into_the_cameras_rotation_over_the_frames():
    """`types.chained_image_rotation`: R_wc,0^T R_wc,L from the frames' R_cp (R_wc,k = R_wc,k-1 R_cp^T);
    None where one is missing."""
    from uareme_fusion.types import chained_image_rotation

    visuals, R_wc = _stream(0.0, 6, seed=2, image_std_rad=0.0)
    chain = chained_image_rotation(v.R_cp for v in visuals[1:])
    np.testing.assert_allclose(chain, R_wc[0].T @ R_wc[-1], atol=1e-12)
    assert chained_image_rotation([visuals[1].R_cp, None]) is None
    np.testing.assert_array_equal(chained_image_rotation([]), np.eye(3))
