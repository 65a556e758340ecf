"""`compare`: several backends on the same visual rotations, table/JSON/plot outputs, dataset loading,
and clear errors for a bad SOURCE."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.evaluation.compare import compare
from uareme_fusion.evaluation.sequence import synthetic_sequence
from uareme_fusion.evaluation.source_sequence import load_sequence
from uareme_fusion.errors import InputError
from uareme_fusion.rotations import quat_xyzw
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.sim.trajectory import make_trajectory


@pytest.fixture(scope="module")
def walk_sequence():
    return synthetic_sequence("walk", seed=1, duration_s=5.0, drop_fraction=0.15, bad_fraction=0.05)


def test_synthetic_sequence_matches_the_simulator_and_counts_dropped_frames(walk_sequence):
    seq = walk_sequence
    traj = make_trajectory("walk", 5.0, seed=1)
    np.testing.assert_allclose(seq.R_wc_true, traj.sample(seq.t_frame_s).R_wc)
    assert len(seq.visuals) == len(seq.t_frame_s) == 75
    n_missing = sum(v is None for v in seq.visuals)
    assert 0 < n_missing < 30 and seq.visuals[0] is not None
    assert f"{n_missing} dropped" in seq.notes[0]
    assert seq.has_imu and seq.imu_gyro_rad_s.shape == (len(seq.imu_t_s), 3)


def test_compare_writes_table_json_and_plot_with_sane_numbers(walk_sequence, tmp_path):
    doc = compare(walk_sequence, tmp_path / "out")
    for name in ("compare.md", "compare.json", "compare.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    assert (tmp_path / "out" / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    saved = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert saved == json.loads(json.dumps(doc))
    rows = doc["backends"]
    assert set(rows) == {"single", "smoother", "smoother-gyro", "mekf"}
    for name in ("single", "smoother", "smoother-gyro"):
        assert rows[name]["frames"] == 75 and rows[name]["latency_ms_median"] > 0
    # The smoother is consistent where the single-frame chain can be poisoned; the gyro helps further.
    assert rows["smoother"]["are_deg_max"] < 15.0
    assert rows["smoother-gyro"]["are_deg_mean"] < rows["smoother"]["are_deg_mean"]
    assert rows["smoother-gyro"]["tilt_deg_mean"] < 2.0
    assert "mekf" in doc["backends"] and ("note" in rows["mekf"] or "are_deg_mean" in rows["mekf"])
    table = (tmp_path / "out" / "compare.md").read_text()
    assert "| smoother-gyro |" in table and "ARE mean" in table
    assert f"{rows['smoother']['are_deg_mean']:.2f}" in table


def write_dataset(root, n=20, fps=10.0, with_imu=True):
    """A minimal dataset in the layout `load_sequence` reads (TUM + EuRoC IMU + normals.npz)."""
    traj = make_trajectory("pan", n / fps + 0.5, seed=3)
    t = np.arange(n) / fps
    rng = np.random.default_rng(3)
    R_cm = traj.R_cm(t)
    maps = [manhattan_normal_map(R, rng, 48, 64, noise_deg=5.0) for R in R_cm]
    root.mkdir()
    np.savez(root / "normals.npz", normals=np.stack([m.normals for m in maps]),
             kappa=np.stack([m.kappa for m in maps]), t_s=t)
    t_gt = np.arange(0, n / fps + 0.4, 0.01)
    R_gt = traj.sample(t_gt).R_wc
    gt = np.column_stack([t_gt, np.zeros((len(t_gt), 3)), quat_xyzw(R_gt)])
    np.savetxt(root / "groundtruth.txt", gt, header="timestamp tx ty tz qx qy qz qw")
    if with_imu:
        from uareme_fusion.sim.imu import simulate_imu

        ti, gyro, accel = simulate_imu(traj, rate_hz=100.0, seed=0)
        (root / "imu0").mkdir()
        np.savetxt(root / "imu0" / "data.csv", np.column_stack([np.rint(ti * 1e9), gyro, accel]), delimiter=",",
                   header="timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z", fmt=["%d"] + ["%.9g"] * 6)  # EuRoC: integer ns
    return traj, t


def test_load_sequence_reads_a_dataset_folder(tmp_path):
    traj, t = write_dataset(tmp_path / "ds")
    seq = load_sequence(tmp_path / "ds")
    np.testing.assert_allclose(seq.t_frame_s, t)
    angle = np.degrees(np.arccos(np.clip((np.einsum("nii->n", np.swapaxes(seq.R_wc_true, 1, 2)
                                                        @ traj.sample(t).R_wc) - 1) / 2, -1, 1)))
    assert angle.max() < 0.05  # slerp of a 100 Hz ground truth
    assert seq.has_imu and all(v is not None for v in seq.visuals)
    doc = compare(seq, tmp_path / "out", names=("single", "smoother"))
    assert doc["backends"]["smoother"]["are_deg_max"] < 5.0


def test_load_sequence_without_imu_or_ground_truth_notes_what_is_missing(tmp_path):
    write_dataset(tmp_path / "ds", with_imu=False)
    (tmp_path / "ds" / "groundtruth.txt").unlink()
    seq = load_sequence(tmp_path / "ds")
    assert not seq.has_imu and seq.R_wc_true is None
    assert any("imu0/data.csv" in n for n in seq.notes) and any("groundtruth" in n for n in seq.notes)
    doc = compare(seq, tmp_path / "out", names=("smoother", "smoother-gyro"))
    assert "no IMU" in doc["backends"]["smoother-gyro"]["note"]
    assert "are_deg_mean" not in doc["backends"]["smoother"]
    assert (tmp_path / "out" / "compare.png").is_file()


def test_bad_sources_give_input_errors_naming_the_problem(tmp_path):
    with pytest.raises(InputError, match="no such dataset folder"):
        load_sequence(tmp_path / "nope")
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(InputError, match="got a file"):
        load_sequence(tmp_path / "file.txt")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no normals"):
        load_sequence(tmp_path / "empty")
    (tmp_path / "badshape").mkdir()
    np.savez(tmp_path / "badshape" / "normals.npz", normals=np.zeros((4, 5, 3)))
    with pytest.raises(InputError, match=r"\(N, H, W, 3\)"):
        load_sequence(tmp_path / "badshape")
    with pytest.raises(InputError, match="unknown trajectory"):
        synthetic_sequence("moon", duration_s=1.0)


def test_cli_compare_synthetic_and_bad_source(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["compare", "--synthetic", "static", "--duration-s", "2", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "| smoother |" in result.output and (tmp_path / "compare.json").is_file()
    result = runner.invoke(app, ["compare", str(tmp_path / "missing"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "no such file or folder" in result.output
    result = runner.invoke(app, ["compare", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
