"""The IMU's delay against an optical reference, measured from gyro and reference alone, and the
BROAD benchmark's pairing of estimate times with samples (benchmarks)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.benchmarks.reference_timing import imu_delay_s, retimed_reference

RATE_HZ = 285.714


def late_imu(delay_s: float, seconds: float = 8.0):
    """A body turning with smooth rates about all axes: `(t (N,), gyro (N, 3) interval samples whose
    readings come `delay_s` late, R_ref (N, 3, 3) the true attitude at t)`."""
    t = np.arange(int(seconds * RATE_HZ)) / RATE_HZ

    def attitude(times):
        return Rotation.from_rotvec(np.stack([np.sin(2 * np.pi * 0.7 * times), 0.8 * np.cos(2 * np.pi * 1.1 * times),
                                              0.5 * np.sin(2 * np.pi * 0.3 * times + 1.0)], axis=1))

    gyro = (attitude(t - 1 / RATE_HZ - delay_s).inv() * attitude(t - delay_s)).as_rotvec() * RATE_HZ
    return t, gyro, attitude(t).as_matrix()


@pytest.mark.parametrize("delay_samples", [0.0, 0.65, -0.4])
def test_delay_of_a_late_imu_is_found_to_a_twentieth_of_a_sample(delay_samples):
    t, gyro, R_ref = late_imu(delay_samples / RATE_HZ)
    R_ref[100:110] = np.nan  # the optical system lost the markers for a moment
    found = imu_delay_s(t, gyro, R_ref, np.ones(t.size, bool)) * RATE_HZ
    assert found == pytest.approx(delay_samples, abs=0.06)


def test_retimed_reference_reads_earlier_and_keeps_gaps():
    t, _, R_ref = late_imu(0.0, seconds=2.0)
    R_ref[50] = np.nan
    R = retimed_reference(t, R_ref, 2.0 / RATE_HZ)
    assert np.isnan(R[50]).all()
    np.testing.assert_allclose(R[200], R_ref[198], atol=1e-9)


def test_broad_bench_pairs_rounded_times_with_their_own_samples():
    from uareme_fusion.benchmarks.broad import nearest_sample

    t = np.arange(5000) / RATE_HZ
    rounded = np.array([float("%.9f" % x) for x in t])
    assert (np.searchsorted(t, rounded) != np.arange(t.size)).any()  # what the benchmark did
    np.testing.assert_array_equal(nearest_sample(t, rounded, RATE_HZ), np.arange(t.size))
