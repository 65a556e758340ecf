"""The visual-only EKF's persistent visual error as a state (`image_rotation_motion.visual_bias_predict`,
`MekfConfig.image_rotation_visual_bias_std_rad`): the prediction against its model, noiseless
convergence, and a seeded stream whose frames err by a Gauss-Markov rotation plus white noise, followed
better than by the filter that takes the frames as independent, with a consistent covariance. Navlie style."""

from __future__ import annotations

import numpy as np
import pytest

from jacobians import fd_jacobian

from uareme_fusion.backends.mekf import Mekf, MekfConfig
from uareme_fusion.backends.mekf.image_rotation_motion import visual_bias_predict
from uareme_fusion.backends.mekf.state import MF, N_STATE, TH
from uareme_fusion.rotations import exp_so3, log_so3, nees
from uareme_fusion.types import VisualRotation

from test_visual_only_labelling import are_deg, handheld_truth

FPS = 30.0


def biased_stream(t, R_wc, bias_std_rad, tau_s, white_std_rad, cp_std_rad, seed):
    """Frames of `R_wc` whose `R_cm = R_wc^T Exp(b) Exp(w)`: `b` Gauss-Markov (steady std `bias_std_rad`
    per axis, correlation `tau_s`), `w` white (`white_std_rad`, the stated covariance); image rotations
    with white noise `cp_std_rad`."""
    rng = np.random.default_rng(seed)
    rho = np.exp(-1.0 / (FPS * tau_s))
    b = rng.normal(0.0, bias_std_rad, 3)
    frames = []
    for k, R in enumerate(R_wc):
        b = rho * b + np.sqrt(1.0 - rho**2) * rng.normal(0.0, bias_std_rad, 3)
        R_cm = R.T @ exp_so3(b) @ exp_so3(rng.normal(0.0, white_std_rad, 3))
        R_cp = None
        if k:
            R_cp = exp_so3(rng.normal(0.0, cp_std_rad, 3)) @ R.T @ R_wc[k - 1]
        frames.append(VisualRotation(R_cm=R_cm, cov=max(white_std_rad, 1e-6)**2 * np.eye(3), cost=0.0,
                                     iterations=1, n_valid=100, R_cp=R_cp, R_cp_std_rad=max(cp_std_rad, 1e-6)))
    return frames


def run(filt, t, frames):
    return [filt.process_frame(float(t_s), v) for t_s, v in zip(t, frames)]


def with_bias(std_rad, tau_s, **keys):
    return Mekf(MekfConfig(mode="visual_only", visual_noise_share_frames=0,
                           image_rotation_visual_bias_std_rad=std_rad,
                           image_rotation_visual_bias_correlation_s=tau_s, **keys))


def test_the_bias_prediction_is_gauss_markov_on_the_manhattan_block():
    """`R_wm` shrinks towards the identity by `rho` (its Jacobian in the error is `rho I` to first
    order), the cross-covariances by `rho`, and the block gains `std^2 (1 - rho^2)`; the rest is kept."""
    rng = np.random.default_rng(2)
    filt = with_bias(0.03, 1.5)
    A = rng.normal(size=(N_STATE, N_STATE))
    P0, R_wm0 = 1e-3 * A @ A.T, exp_so3(np.radians([1.0, -2.0, 0.5]))
    filt.P, filt.R_wm = P0, R_wm0
    dt = 1.0 / FPS
    rho = np.exp(-dt / 1.5)
    visual_bias_predict(filt, dt, 0.03, 1.5)
    np.testing.assert_allclose(log_so3(filt.R_wm), rho * log_so3(R_wm0), atol=1e-12)
    fd = fd_jacobian(lambda d: log_so3(filt.R_wm.T @ exp_so3(rho * log_so3(R_wm0 @ exp_so3(d)))), 3)
    np.testing.assert_allclose(fd, rho * np.eye(3), atol=2e-3)  # the Gauss-Markov model's F, first order in b
    P = filt.P
    np.testing.assert_allclose(P[MF, MF], rho**2 * P0[MF, MF] + 0.03**2 * (1 - rho**2) * np.eye(3), atol=1e-15)
    np.testing.assert_allclose(P[TH, MF], rho * P0[TH, MF], atol=1e-15)
    np.testing.assert_allclose(P[TH, TH], P0[TH, TH], atol=0)
    np.testing.assert_allclose(P, P.T)


def test_the_bias_state_converges_without_noise():
    t, R_wc = handheld_truth(3.0)
    frames = biased_stream(t, R_wc, 0.0, 1.0, 0.0, 0.0, 0)
    filt = with_bias(np.radians(2.0), 1.0)
    ests = run(filt, t, frames)
    assert are_deg(ests, R_wc).max() < 1e-3
    assert np.degrees(np.linalg.norm(log_so3(filt.R_wm))) < 1e-3
    assert filt.counters["visual_ignored"] == filt.counters["reinitialised"] == 0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_persistent_visual_error_is_followed_better_with_the_bias_state_and_consistently(seed):
    """Frames 3 deg off by a 1 s Gauss-Markov error plus 0.5 deg white noise (stated), image rotations
    0.3 deg: with the bias state the filter follows the truth better than taking the frames as stated
    (independent), and its NEES is near 3 (seeded)."""
    t, R_wc = handheld_truth(12.0)
    frames = biased_stream(t, R_wc, np.radians(3.0), 1.0, np.radians(0.5), np.radians(0.3), seed)
    biased, plain = run(with_bias(np.radians(3.0), 1.0), t, frames), run(with_bias(0.0, 1.0), t, frames)
    are_biased, are_plain = are_deg(biased, R_wc), are_deg(plain, R_wc)
    assert are_biased.mean() < 0.8 * are_plain.mean(), (are_biased.mean(), are_plain.mean())
    n = nees(np.array([e.R_wc for e in biased]), R_wc, np.array([e.cov for e in biased]))[30:]
    assert 1.0 < n.mean() < 6.0, n.mean()
