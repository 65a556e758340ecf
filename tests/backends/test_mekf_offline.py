"""`run`/`eval --offline` on a recorded IMU-only file (issue 17): the forward-backward smoother."""

import pytest


def test_offline_eval_of_a_recorded_broad_file_beats_the_streaming_filter(shared_data, tmp_path):
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.session import run_to_folder

    trial = shared_data / "broad_subset" / "02_undisturbed_slow_rotation_B.hdf5"
    if not trial.is_file():
        pytest.skip(f"{trial} not found")
    tilt = {}
    for offline in (False, True):
        cfg = RunConfig(mekf_preset="imu_only", offline=offline)
        summary = run_to_folder(str(trial), tmp_path / str(offline), cfg, evaluate=True, command="eval")
        assert summary["stopped"] == "end"
        tilt[offline] = summary["tilt_deg"]["mean"]
    assert tilt[True] < 0.92 * tilt[False], tilt  # measured 0.27 vs 0.31 deg


def test_offline_refuses_a_source_with_frames(tmp_path):
    from uareme_fusion.errors import InputError
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.session import run_to_folder

    with pytest.raises(InputError, match="--offline"):
        run_to_folder("sim:room", tmp_path, RunConfig(offline=True, max_frames=3, normals="source"))
