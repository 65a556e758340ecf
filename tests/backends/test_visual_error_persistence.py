"""The visual errors' learned correlation time (`backends/visual_error_persistence.py`), on synthetic
streams whose errors are white or Gauss-Markov, and the EKF reading it."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.backends.visual_error_persistence import VisualErrorPersistence, correlation_from_ratio
from uareme_fusion.types import VisualRotation

DT_S = 1.0 / 30.0


def stream(rho: float, n: int = 900, err_std_rad: float = np.radians(2.0), cp_std_rad: float = np.radians(0.3),
           seed: int = 0):
    """(t_s, visuals) of a turning camera: each frame's `R_cm` errs by an AR(1) error of frame-to-frame
    correlation `rho` and per-axis std `err_std_rad`; `R_cp` by white noise of `cp_std_rad`."""
    rng = np.random.default_rng(seed)
    R_wc = np.eye(3)
    e = rng.normal(0.0, err_std_rad, 3)
    rate = np.zeros(3)
    visuals, R_prev = [], None
    for _ in range(n):
        rate = 0.98 * rate + rng.normal(0.0, 0.3, 3)
        R_wc = R_wc @ Rotation.from_rotvec(rate * DT_S).as_matrix()
        e = rho * e + np.sqrt(1.0 - rho**2) * rng.normal(0.0, err_std_rad, 3)
        R_cm = R_wc.T @ Rotation.from_rotvec(e).as_matrix()
        R_cp = None
        if R_prev is not None:
            R_cp = Rotation.from_rotvec(rng.normal(0.0, cp_std_rad, 3)).as_matrix().T @ (R_wc.T @ R_prev)
        visuals.append(VisualRotation(R_cm=R_cm, cov=err_std_rad**2 * np.eye(3), cost=0.0, iterations=1,
                                      n_valid=100, R_cp=R_cp, R_cp_std_rad=cp_std_rad))
        R_prev = R_wc
    return np.arange(n) * DT_S, visuals


def learned_tau_s(rho: float, lag_frames: int = 4, **kw) -> float:
    est = VisualErrorPersistence(lag_frames, frames=300.0, max_s=10.0)
    for t, v in zip(*stream(rho, **kw)):
        est.update(t, v)
    return est.tau_s


def test_correlation_from_ratio_inverts_the_structure_function():
    for rho in (0.2, 0.6, 0.9, 0.99):
        ratio = (1 - rho**8) / (1 - rho)
        assert correlation_from_ratio(ratio, 8) == pytest.approx(rho, abs=1e-9)
    assert correlation_from_ratio(0.7, 8) == 0.0
    assert correlation_from_ratio(9.0, 8) == 1.0


def test_white_errors_give_no_correlation_time():
    taus = [learned_tau_s(0.0, seed=s) for s in range(3)]
    assert max(taus) < 0.4 * DT_S, taus  # well under one frame: the EKF's scale (1 + rho) / (1 - rho) ~ 1


@pytest.mark.parametrize("tau_true_s", [0.1, 0.3])
def test_gauss_markov_errors_give_their_correlation_time(tau_true_s):
    rho = np.exp(-DT_S / tau_true_s)
    taus = [learned_tau_s(rho, seed=s) for s in range(3)]
    assert np.median(taus) == pytest.approx(tau_true_s, rel=0.35), taus


def test_chain_breaks_without_an_image_rotation():
    est = VisualErrorPersistence(4)
    t, visuals = stream(0.9, n=6)
    for k in range(5):
        est.update(t[k], visuals[k])
    assert len(est._history) == 4  # the first frame has no image rotation: the chain starts at the second
    est.update(t[5], None)
    assert est._history == [] and est.tau_s == 0.0


def test_mekf_fuses_by_the_learned_time_only_when_asked():
    from uareme_fusion.backends.mekf import Mekf, MekfConfig

    t, visuals = stream(np.exp(-DT_S / 0.3), n=900)
    scales = {}
    for lag in (0, 4):
        f = Mekf(MekfConfig(image_rotation_error_persistence_lag_frames=lag))
        for tk, v in zip(t, visuals):
            f.process_frame(tk, v)
        persistence = f.motion.persistence
        f.t_visual_s = f.t_state - DT_S  # as when the next frame comes, predicted by its image rotation
        scales[lag] = (None if persistence is None else persistence.tau_s, f.motion.visual_noise_scale(f))
    assert scales[0][0] is None
    tau_s, scale = scales[4]
    assert 0.1 < tau_s < 0.6  # the default 100-frame average: noisier than the 300 frames above
    rho = np.exp(-DT_S / tau_s)
    assert scale == pytest.approx((1 + rho) / (1 - rho), rel=1e-6)
