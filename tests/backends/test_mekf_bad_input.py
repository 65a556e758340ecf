"""Bad IMU input for the MEKF: NaN/Inf dropped and counted, reordering, duplicates, late samples,
gaps inflate the covariance, saturation flagged, and no stream makes the state NaN."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uareme_fusion.backends.imu_stream import ImuStream
from uareme_fusion.backends.mekf import TH, Mekf, MekfConfig
from uareme_fusion.config import load_config
from uareme_fusion.errors import InputError
from uareme_fusion.types import Status

UP_C = np.array([0.0, -9.81, 0.0])  # an upright OpenCV camera at rest reads +g along -y


def still_samples(n, rate_hz=200.0, t0=0.0):
    t = t0 + np.arange(n) / rate_hz
    return t, np.zeros((n, 3)), np.tile(UP_C, (n, 1))


def test_nonfinite_samples_are_dropped_and_counted():
    t, g, a = still_samples(50)
    g[5, 0] = np.nan
    a[7, 2] = np.inf
    t[9] = np.nan
    filt = Mekf()
    filt.process_imu(t, g, a)
    est = filt.process_frame(0.3, None)
    assert filt.stream.counts.nonfinite == 3
    assert Status.IMU_DROPPED in est.status
    assert np.all(np.isfinite(est.R_wc)) and np.all(np.isfinite(est.cov))


def test_small_reordering_is_undone_and_duplicates_and_late_samples_are_counted():
    stream = ImuStream(reorder_window_s=0.02)
    t, g, a = still_samples(20)
    g[:, 0] = t  # tag each sample with its time
    order = np.arange(20)
    order[[3, 4]] = order[[4, 3]]  # swapped neighbours: 5 ms out of order
    out1 = stream.push(t[order], g[order], a[order])
    out2 = stream.push(t[[18]], g[[18]] + 1.0, a[[18]])  # a duplicate of a held stamp: first one kept
    late = stream.push(t[[0]] , g[[0]], a[[0]])  # older than what was released
    rest = stream.flush()
    released = np.concatenate([out1.t_s, out2.t_s, late.t_s, rest.t_s])
    np.testing.assert_array_equal(released, t)
    np.testing.assert_array_equal(np.concatenate([out1.gyro_rad_s, rest.gyro_rad_s])[:, 0], t)
    assert stream.counts.duplicate == 1 and stream.counts.late == 1


def test_checked_rows_are_held_as_a_copy_and_count_nothing():
    stream = ImuStream(reorder_window_s=0.02)
    t, g, a = still_samples(10)
    rows = np.column_stack([t, g, a, np.zeros(10)])
    stream.add_checked_rows(rows[:6])  # into an empty buffer, as `Mekf` puts back a staged batch
    stream.add_checked_rows(rows[6:])  # after what is held
    rows[:, 1] = 7.0  # the caller reuses its array
    released = stream.flush()
    np.testing.assert_array_equal(released.t_s, t)
    assert not released.gyro_rad_s.any() and stream.newest_s == t[-1]
    assert stream.counts == type(stream.counts)()


def test_wrong_shapes_raise_input_error_naming_them():
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        Mekf().process_imu(np.zeros(3), np.zeros((3, 2)), np.zeros((3, 3)))


def test_gap_inflates_the_covariance_instead_of_integrating():
    cfg = MekfConfig(imu_gap_limit_s=0.1, unknown_rate_std_rad_s=2.0)
    filt = Mekf(cfg)
    t, g, a = still_samples(100)
    filt.process_imu(t, g, a)
    before = filt.process_frame(t[-1], None)
    t2, g2, a2 = still_samples(10, t0=t[-1] + 0.5)
    g2[:] = 3.0  # garbage rate that would rotate 1.5 rad if integrated over the gap
    filt.process_imu(t2[:1], g2[:1], a2[:1])
    after = filt.process_frame(t2[0], None)
    assert Status.IMU_GAP in after.status
    assert np.trace(after.cov) > np.trace(before.cov) + 3 * (2.0 * 0.5) ** 2 * 0.9
    assert np.degrees(np.arccos((np.trace(before.R_wc.T @ after.R_wc) - 1) / 2)) < 1.0


def test_saturated_gyro_is_flagged_and_inflates_the_covariance():
    cfg = MekfConfig(gyro_range_rad_s=5.0)
    filt = Mekf(cfg)
    t, g, a = still_samples(60)
    filt.process_imu(t[:40], g[:40], a[:40])
    before = filt.process_frame(t[39], None)
    g[40:45, 2] = 5.0
    filt.process_imu(t[40:], g[40:], a[40:])
    est = filt.process_frame(t[-1], None)
    assert Status.GYRO_SATURATED in est.status and Status.GYRO_SATURATED not in before.status
    assert filt.stream.counts.saturated == 5
    assert est.cov[1, 1] > before.cov[1, 1] + 0.8 * 5 * (2.0 * 0.005) ** 2  # yaw axis: 5 samples of unknown rate


@pytest.mark.parametrize("preset", [None, "imu_only"])  # defaults; low-pass, rest and rate noise on
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(
        st.tuples(
            st.one_of(st.floats(-1.0, 5.0), st.sampled_from([np.nan, np.inf, -np.inf])),
            st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=6, max_size=6),
        ),
        min_size=1,
        max_size=40,
    ),
    st.lists(st.floats(0.0, 6.0), min_size=1, max_size=5),
)
def test_no_input_stream_makes_the_state_nan(preset, samples, frame_times):
    filt = Mekf(MekfConfig(mode="imu_only") if preset is None else load_config(preset, MekfConfig))
    t = np.array([s[0] for s in samples])
    values = np.array([s[1] for s in samples], dtype=float)
    half = len(samples) // 2
    filt.process_imu(t[:half], values[:half, :3], values[:half, 3:])
    for t_f in sorted(frame_times):
        est = filt.process_frame(t_f, None)
        filt.process_imu(t[half:], values[half:, :3], values[half:, 3:])
        assert np.all(np.isfinite(est.R_wc)) and np.all(np.isfinite(est.cov))
        np.testing.assert_allclose(est.R_wc.T @ est.R_wc, np.eye(3), atol=1e-6)
        assert np.linalg.det(est.R_wc) > 0
        assert np.all(np.isfinite(filt.P)) and np.all(np.isfinite(filt.b_c))
    filt.flush()
    assert np.all(np.isfinite(filt.R_wc)) and np.all(np.isfinite(filt.P[TH, TH]))
