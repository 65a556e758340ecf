"""The evaluation package: one set of statistics, one backend factory that `run` and `compare` share."""

from __future__ import annotations

import numpy as np
import pytest

from uareme_fusion.drivers.base import SourceInfo
from uareme_fusion.errors import InputError
from uareme_fusion.backends.factory import BACKEND_NAMES, backend_kind, knows_gravity, make_backend
from uareme_fusion.scoring.statistics import error_stats, rmse
from uareme_fusion.pipeline import RunConfig
from uareme_fusion.pipeline.stages import backend_for_run


def test_statistics_are_the_textbook_ones():
    values = np.array([3.0, -4.0, 0.0, 1.0, 10.0])
    stats = error_stats(values, ("mean", "median", "rmse", "p95", "max", "min"))
    assert stats == {"mean": 2.0, "median": 1.0, "rmse": pytest.approx(np.sqrt(126 / 5)),
                     "p95": pytest.approx(8.6), "max": 10.0, "min": -4.0}
    assert rmse(np.array([[3.0, 4.0]])) == pytest.approx(np.sqrt(12.5))
    assert all(type(v) is float for v in stats.values())  # plain floats for JSON


@pytest.mark.parametrize("name", BACKEND_NAMES)
def test_each_backend_is_made_under_its_own_name(name):
    assert make_backend(name).name == name


def test_knows_gravity_only_with_an_imu_and_only_for_imu_backends():
    assert [knows_gravity(n, has_imu=True) for n in BACKEND_NAMES] == [False, False, True, True]
    assert not any(knows_gravity(n, has_imu=False) for n in BACKEND_NAMES)
    assert backend_kind("smoother", has_imu=True).name == "smoother-gyro"  # what `run` builds
    assert backend_kind("smoother", has_imu=False).name == "smoother"
    with pytest.raises(InputError, match="unknown backend 'ekf'; valid: single, smoother"):
        backend_kind("ekf")


@pytest.mark.parametrize("has_imu", [False, True])
def test_run_and_compare_build_the_same_smoother(has_imu):
    """`run --backend smoother` builds, through the same factory, the backend `compare` names
    smoother (no IMU) or smoother-gyro (with an IMU), with the same settings, for a source of known K
    (without, `run` widens the paper smoother's rate bias: `smoother.SCENE_K_IMAGE_ROTATION_BIAS`)."""
    info = SourceInfo(name="test", has_imu=has_imu, K=np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]))
    from_run = backend_for_run(RunConfig(backend="smoother"), info)
    from_compare = make_backend("smoother-gyro" if has_imu else "smoother")
    assert from_run.name == from_compare.name
    assert from_run.config.model_dump() == from_compare.config.model_dump()


def test_run_applies_the_source_imu_geometry_and_overrides_to_the_ekf():
    R_ci = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    info = SourceInfo(name="test", has_imu=True, R_ci=R_ci, imu_time_offset_s=0.02)
    mekf = backend_for_run(RunConfig(mekf={"gyro_noise_rad_s_sqrt_hz": 0.005}), info)
    np.testing.assert_array_equal(mekf.config.R_ci, R_ci)
    assert mekf.config.imu_time_offset_s == 0.02  # one convention end to end: t_cam = t_imu + offset
    assert mekf.config.gyro_noise_rad_s_sqrt_hz == 0.005


def test_compare_reads_a_simulated_folder_as_run_does(tmp_path):
    """A frame the simulator marks dropped has no usable pixel for `compare` (no visual rotation),
    and the IMU is rotated and shifted by scene.json, as by `run`'s TUM driver."""
    from uareme_fusion.drivers.tum import TumSource
    from uareme_fusion.evaluation.source_sequence import load_sequence, source_sequence
    from uareme_fusion.sim.dataset import SequenceOptions, write_sequence

    out = tmp_path / "sim"
    R_ci = ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # a phone's IMU axes, 13 ms late
    write_sequence("room", out, SequenceOptions(frames=5, width=32, height=24, fps=10.0, seed=2, R_ci=R_ci,
                                                imu_time_offset_s=-0.013))
    path = out / "normals" / "000002.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    np.savez(path, **{**arrays, "dropped": np.bool_(True)})
    seq = load_sequence(out)
    assert [v is None for v in seq.visuals] == [False, False, True, False, False]
    assert any("1 normal maps had no valid normals" in n for n in seq.notes)
    with TumSource(out) as tum:
        from_run = source_sequence(tum, RunConfig(normals="source"))
    assert [v is None for v in from_run.visuals] == [v is None for v in seq.visuals]
    np.testing.assert_allclose(seq.t_frame_s, from_run.t_frame_s)
    np.testing.assert_allclose(seq.R_wc_true, from_run.R_wc_true, atol=1e-12)
    # the IMU on the camera clock and axes, from scene.json, as the driver puts it
    for a, b in zip((seq.imu_t_s, seq.imu_gyro_rad_s, seq.imu_accel_m_s2),
                    (from_run.imu_t_s, from_run.imu_gyro_rad_s, from_run.imu_accel_m_s2)):
        np.testing.assert_allclose(a, b, atol=1e-9)
