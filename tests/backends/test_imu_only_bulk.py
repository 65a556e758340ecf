"""IMU-only runs in bulk (issue 17): `Mekf.process_imu_segments` gives what feeding the batches one by
one gives, bad samples included; the runner's bulk path writes the same files as one result at a
time, and a full disk leaves both tables complete and in step with the summary's counts."""

from __future__ import annotations

import os

import numpy as np
import pytest

from uareme_fusion.backends.base import Backend
from uareme_fusion.backends.mekf import Mekf, MekfConfig
from uareme_fusion.backends.mekf import segments as mekf_segments
from uareme_fusion.config import load_config
from uareme_fusion.drivers.base import Source, SourceInfo
from uareme_fusion.drivers.interleave import split_by_span
from uareme_fusion.pipeline.runner import Pipeline
from uareme_fusion.sinks.estimate_files import EstimateLog, EstimatesCsvWriter, TumTrajectoryWriter
from uareme_fusion.sim.imu import simulate_imu
from uareme_fusion.sim.trajectory import make_trajectory
from uareme_fusion.types import Status


def imu_log(seed: int = 0, duration_s: float = 20.0, bad: bool = True):
    """(t, gyro, accel) of a simulated walk at 200 Hz with a gyro bias; `bad`: NaN rows, repeated
    and out-of-order stamps, a 0.3 s gap and a burst of saturated gyro readings."""
    traj = make_trajectory("walk", duration_s=duration_s, seed=seed)
    t, gyro, accel = simulate_imu(traj, rate_hz=200.0, seed=seed + 1)
    gyro = gyro + np.array([0.01, -0.02, 0.015])
    if bad:
        gyro[700] = np.nan
        accel[1500, 2] = np.inf
        t[2001] = t[2000]                      # repeated stamp
        t[2600], t[2601] = t[2601], t[2600]    # swapped (within the reorder window)
        gap = (t > 12.0) & (t < 12.3)
        t, gyro, accel = t[~gap], gyro[~gap], accel[~gap]
        gyro[3000:3010, 0] = 40.0              # beyond the 34.9 rad/s range
    return t, gyro, accel


def batch_ends(t: np.ndarray) -> np.ndarray:
    zeros = np.zeros((t.size, 3))
    return np.cumsum([len(b) for b in split_by_span(t, zeros, zeros, 1.0 / 30.0)])


@pytest.mark.parametrize("R_ci", [np.eye(3), np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]])])
def test_bulk_estimates_are_those_of_batch_by_batch(R_ci):
    t, gyro, accel = imu_log()
    cfg = load_config("imu_only", MekfConfig).model_copy(update={"R_ci": R_ci.tolist()})
    bulk, one_by_one = Mekf(cfg), Mekf(cfg)
    ends = batch_ends(t)
    a = bulk.process_imu_segments(t, gyro, accel, ends)
    b = Backend.process_imu_segments(one_by_one, t, gyro, accel, ends)
    assert len(a) == len(b) == ends.size
    np.testing.assert_array_equal(a.t_s, t[ends - 1])
    np.testing.assert_allclose(a.R_wc, b.R_wc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(a.gyro_bias_rad_s, b.gyro_bias_rad_s, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.status, b.status)
    assert bulk.counters == one_by_one.counters and bulk.stream.counts == one_by_one.stream.counts
    flags = np.bitwise_or.reduce(a.status)
    for flag in (Status.IMU_DROPPED, Status.IMU_GAP, Status.GYRO_SATURATED):
        assert flags & flag, flag
    assert bulk.counters["accel_updates"] > 50 and bulk.stream.counts.nonfinite == 2


def test_clean_stream_takes_one_kernel_call_per_bulk(monkeypatch):
    t, gyro, accel = imu_log(bad=False)
    filt = Mekf(load_config("imu_only", MekfConfig))
    filt.process_imu_segments(t[:100], gyro[:100], accel[:100], [50, 100])  # initialises (segment by segment)
    calls = []
    real = mekf_segments.integrate_segments
    monkeypatch.setattr(mekf_segments, "integrate_segments", lambda *a: calls.append(1) or real(*a))
    ends = 100 + batch_ends(t[100:])
    out = filt.process_imu_segments(t[100:], gyro[100:], accel[100:], ends - 100)
    assert calls == [1] and len(out) == ends.size and not (out.status & ~int(Status.ACCEL_DOWNWEIGHTED)).any()


class ImuOnlySource(Source):
    def __init__(self, t, gyro, accel):
        self.t, self.gyro, self.accel = t, gyro, accel
        self.info = SourceInfo(name="log", n_frames=0, has_frames=False, has_imu=True)

    def events(self):
        yield from split_by_span(self.t, self.gyro, self.accel)


class RowByRow:
    """A sink without `write_many`: the runner hands it (and the others) one result at a time."""

    def write(self, result):
        pass

    def close(self):
        pass


def run_into(out, source, *extra, max_frames=None):
    out.mkdir()
    sinks = [TumTrajectoryWriter(out / "trajectory.tum"), EstimatesCsvWriter(out / "estimates.csv"), *extra]
    stats = Pipeline(None, Mekf(load_config("imu_only", MekfConfig)), sinks).run(source, max_frames=max_frames)
    return stats


def test_bulk_files_are_those_written_one_result_at_a_time(tmp_path):
    source = ImuOnlySource(*imu_log(duration_s=30.0))  # over 256 batches: two bulks
    bulk, single = run_into(tmp_path / "bulk", source), run_into(tmp_path / "single", source, RowByRow())
    assert bulk.estimates == single.estimates == 891 and bulk.stopped == single.stopped == "end"  # 9 in the gap
    assert bulk.status_counts == single.status_counts and bulk.status_counts["IMU_GAP"] >= 1
    for name in ("trajectory.tum", "estimates.csv"):
        assert (tmp_path / "bulk" / name).read_bytes() == (tmp_path / "single" / name).read_bytes()
    lines = (tmp_path / "bulk" / "estimates.csv").read_text().splitlines()
    assert len(lines) == 892 and lines[-1].split(",")[-13:] == ["0"] + [""] * 12  # status, flags, no shares, no steady part
    log = EstimateLog()
    limited = run_into(tmp_path / "limited", source, log, max_frames=300)
    assert limited.estimates == 300 and limited.stopped == "max_frames" and log.arrays()[0].size == 300


def test_a_full_disk_in_a_bulk_keeps_both_tables_whole_and_in_step(tmp_path, monkeypatch):
    real_write = os.write
    writes = []

    def fill_on_the_fourth(fd, data):  # tum, csv of the first bulk, then tum, and the csv fails
        writes.append(len(data))
        if len(writes) == 4:
            raise OSError(28, "No space left on device")
        return real_write(fd, data)

    source = ImuOnlySource(*imu_log(duration_s=30.0, bad=False))
    out = tmp_path / "out"
    out.mkdir()
    sinks = [TumTrajectoryWriter(out / "trajectory.tum"), EstimatesCsvWriter(out / "estimates.csv")]
    monkeypatch.setattr(os, "write", fill_on_the_fourth)  # after the two header rows
    stats = Pipeline(None, Mekf(load_config("imu_only", MekfConfig)), sinks).run(source)
    monkeypatch.undo()
    assert stats.stopped == "output_error" and "No space left on device" in stats.error
    assert stats.estimates == 256
    tum = [ln for ln in (out / "trajectory.tum").read_text().splitlines() if not ln.startswith("#")]
    csv_lines = (out / "estimates.csv").read_text().splitlines()
    assert len(tum) == 256 and len(csv_lines) == 257
    assert all(len(r.split()) == 8 for r in tum) and all(ln.count(",") == 33 for ln in csv_lines)
