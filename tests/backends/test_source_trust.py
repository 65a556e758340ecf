"""The camera's trust in `Mekf` (`backends/mekf/source_trust.py`) and the filter on bad input:
persistent and independent visual errors, NaN covariances, an IMU that stops, a camera that goes black."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.backends.mekf import Mekf, MekfConfig
from uareme_fusion.backends.mekf import source_trust
from uareme_fusion.backends.mekf.state_buffer import S_SIZE, S_TRUST_FRAMES, new_state_buffer
from uareme_fusion.types import Status, VisualRotation

R_CM = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # camera upright, scene aligned with the world
R_WC = R_CM.T
UP_C = R_WC[2]
IMU_HZ, FPS = 200.0, 20.0


def _scalars() -> np.ndarray:
    return new_state_buffer()[:S_SIZE]


def _tilt_deg(R_wc: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(R_wc[2] @ UP_C, -1.0, 1.0))))


def test_independent_errors_keep_the_camera_fully_trusted():
    rng = np.random.default_rng(0)
    s, v = _scalars(), 1e-3
    shares, persistent = [], []
    for _ in range(300):
        e = rng.normal(0.0, np.sqrt(v), 3)
        e[2] = 0.0
        share, pers = source_trust.update_visual_trust(s, e, v, 30.0, 0.05, 0.0)
        shares.append(share)
        persistent.append(pers)
    assert np.mean(shares[30:]) > 0.8  # the spread matches the stated variance
    assert np.median(persistent[30:]) < v  # no persistent error beyond what noise leaves
    assert source_trust.vertical_variance(s, 1e-4, 30.0) < 10 * v * 30


def test_a_persistent_error_is_found_and_its_independent_share_is_small():
    rng = np.random.default_rng(1)
    s, v, bias = _scalars(), 0.0076, np.array([0.15, 0.0, 0.0])  # 8.6 deg off, 5 deg stated
    for _ in range(100):
        share, pers = source_trust.update_visual_trust(s, bias + rng.normal(0.0, 0.005, 3) * [1, 1, 0], v, 30.0, 0.05,
                                                         0.0)
    assert share == pytest.approx(0.05)  # the frames agree with each other far better than stated
    assert pers == pytest.approx(0.5 * 0.15**2, rel=0.1)  # per tilt axis
    assert source_trust.vertical_variance(s, 1e-4, 30.0) == pytest.approx(1e-4 + 30 * (pers - 4e-4))


def test_vertical_waits_for_samples_and_trust_off_changes_nothing():
    s = _scalars()
    assert source_trust.vertical_variance(s, 1e-4, 30.0) == np.inf
    assert source_trust.vertical_variance(s, 1e-4, 0.0) == 1e-4
    assert source_trust.update_visual_trust(s, np.ones(3), 1.0, 0.0, 0.05, 0.0) == (1.0, 0.0)
    before = s.copy()
    source_trust.update_visual_trust(s, np.full(3, np.nan), 1.0, 30.0, 0.05, 0.0)  # a NaN frame is left out
    seen = np.arange(s.size) == S_TRUST_FRAMES  # ... but for the frames seen
    assert np.array_equal(before[~seen], s[~seen], equal_nan=True) and s[S_TRUST_FRAMES] == before[S_TRUST_FRAMES] + 1


def test_vertical_innovation_is_the_frames_up_minus_the_accelerometers():
    rng = np.random.default_rng(2)
    R_wc, R_wm = Rotation.random(random_state=3).as_matrix(), Rotation.random(random_state=4).as_matrix()
    for _ in range(5):
        r, acc = rng.normal(0, 0.3, 3), rng.normal(0, 5, 3)
        e, v = source_trust.visual_vertical_innovation(R_wc, R_wm, r, np.diag([1e-3, 2e-3, 5e-3]), acc, 0.05,
                                                       1e-4, 1.0, 1e-4)
        up_vis = R_wc.T @ R_wm @ Rotation.from_rotvec(r).as_matrix()[:, 2]
        np.testing.assert_allclose(e, up_vis - acc / np.linalg.norm(acc), atol=1e-12)
        assert v == pytest.approx(1.5e-3 + 1e-4 / 0.05 + 1e-4)
    assert source_trust.visual_vertical_innovation(R_wc, R_wm, r, np.eye(3), acc, 0.0, 1e-4, 1.0, 1e-4)[1] == 0.0


def _stream(filt, seconds, visual_at, imu_until_s=np.inf, seed=0):
    """A static upright camera: IMU (gravity, noise) up to `imu_until_s`, frames at FPS with
    `visual_at(t)` (a VisualRotation or None). Returns the estimates."""
    rng = np.random.default_rng(seed)
    out = []
    t_imu = np.arange(1, int(seconds * IMU_HZ) + 1) / IMU_HZ
    gyro = rng.normal(0, 2e-3, (t_imu.size, 3))
    accel = UP_C * 9.81 + rng.normal(0, 0.05, (t_imu.size, 3))
    start = 0
    for t in np.arange(1, int(seconds * FPS) + 1) / FPS:
        end = int(np.searchsorted(t_imu, min(t, imu_until_s), side="right"))
        if end > start:
            filt.process_imu(t_imu[start:end], gyro[start:end], accel[start:end])
            start = end
        out.append(filt.process_frame(t, visual_at(t)))
    return out


def _biased(tilt_deg=8.0, std_deg=5.0, seed=0):
    """Visual rotations off by a steady tilt with a stated std that does not cover it, frame noise small."""
    rng = np.random.default_rng(seed)

    def at(t):
        err = np.radians([tilt_deg, 0.0, 0.0]) + rng.normal(0, np.radians(0.2), 3)
        return VisualRotation(R_CM @ Rotation.from_rotvec(err).as_matrix(), np.radians(std_deg) ** 2 * np.eye(3),
                              cost=0.0, iterations=1, n_valid=1000)
    return at


@pytest.mark.parametrize("compiled", [True, False])
def test_a_camera_that_keeps_disagreeing_with_a_quiet_accelerometer_loses_the_tilt(compiled):
    trusted = _stream(Mekf(MekfConfig(mode="visual_imu", visual_trust_frames=0, compiled=compiled)), 5.0, _biased())
    learned = _stream(Mekf(MekfConfig(mode="visual_imu", visual_trust_frames=30, compiled=compiled)), 5.0, _biased())
    tilt_trusted = np.mean([_tilt_deg(e.R_wc) for e in trusted[20:]])
    tilt_learned = np.mean([_tilt_deg(e.R_wc) for e in learned[20:]])
    assert tilt_trusted > 2.0  # the old filter: 8 deg of persistent error pulls tilt
    assert tilt_learned < 0.5
    share_accel, share_visual = learned[-1].tilt_shares
    assert share_accel + share_visual == pytest.approx(1.0) and share_visual < share_accel


def test_both_paths_agree_with_the_trust():
    a = _stream(Mekf(MekfConfig(mode="visual_imu", visual_trust_frames=30, compiled=True)), 3.0, _biased())
    b = _stream(Mekf(MekfConfig(mode="visual_imu", visual_trust_frames=30, compiled=False)), 3.0, _biased())
    for ea, eb in zip(a, b):
        np.testing.assert_allclose(ea.R_wc, eb.R_wc, atol=1e-9)
        np.testing.assert_allclose(ea.cov, eb.cov, rtol=1e-6, atol=1e-14)
        np.testing.assert_allclose(ea.tilt_shares, eb.tilt_shares, rtol=1e-6)


@pytest.mark.parametrize("compiled", [True, False])
def test_nan_covariances_are_gated_out_counted_and_never_fused(compiled):
    good = _biased(tilt_deg=0.0, std_deg=1.0)

    def at(t):
        v = good(t)
        return VisualRotation(v.R_cm, np.full((3, 3), np.nan), 0.0, 1, 1000) if 1.0 < t <= 3.0 else v
    filt = Mekf(MekfConfig(mode="visual_imu", compiled=compiled))
    est = _stream(filt, 4.0, at)
    assert all(np.isfinite(e.R_wc).all() and np.isfinite(e.cov).all() for e in est)
    assert filt.counters["visual_nonfinite"] == 40
    assert filt.counters["reinitialised"] == 0
    assert all(Status.VISUAL_REJECTED in e.status for e in est[21:60])
    assert max(_tilt_deg(e.R_wc) for e in est) < 1.0


@pytest.mark.parametrize("compiled", [True, False])
def test_an_imu_that_stops_mid_recording_goes_on_with_vision_and_says_so(compiled):
    filt = Mekf(MekfConfig(mode="visual_imu", compiled=compiled))
    est = _stream(filt, 6.0, _biased(tilt_deg=0.0, std_deg=1.0), imu_until_s=2.0)
    after = est[50:]
    assert any(Status.IMU_GAP in e.status for e in est[40:45])
    assert all(np.isfinite(e.R_wc).all() for e in after)
    assert max(_tilt_deg(e.R_wc) for e in after) < 2.0  # held by the camera
    assert filt.counters["visual_updates"] >= 100


@pytest.mark.parametrize("compiled", [True, False])
def test_a_camera_black_for_two_seconds_goes_on_with_the_imu_and_comes_back(compiled):
    good = _biased(tilt_deg=0.0, std_deg=1.0)
    filt = Mekf(MekfConfig(mode="visual_imu", compiled=compiled))
    est = _stream(filt, 6.0, lambda t: None if 2.0 < t <= 4.0 else good(t))
    black, back = est[41:80], est[85:]
    assert all(Status.VISUAL_MISSING in e.status for e in black)
    assert all(e.tilt_shares[1] == 0.0 for e in black)  # the camera gives nothing
    assert max(_tilt_deg(e.R_wc) for e in black) < 1.0  # the IMU holds the tilt
    assert all(Status.VISUAL_MISSING not in e.status and e.tilt_shares[1] > 0.0 for e in back)
    assert max(_tilt_deg(e.R_wc) for e in back) < 1.0
