"""TUM RGB-D and EuRoC readers: the simulator's files round-trip, and the real data sets load."""


import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.formats.euroc import read_euroc_imu
from uareme_fusion.formats.tum import associate, load_tum_rgbd
from uareme_fusion.errors import InputError
from uareme_fusion.sim.dataset import DEPTH_SCALE, SequenceOptions, write_sequence
from uareme_fusion.sim.imu import simulate_imu
from uareme_fusion.sim.scenarios import build_scenario



@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("bus")
    write_sequence("bus", out, SequenceOptions(frames=6, width=64, height=48, fps=2.0, seed=4, imu_rate_hz=200.0))
    return out


def test_tum_round_trip_of_simulated_sequence(sim_dir):
    seq = load_tum_rgbd(sim_dir)
    assert len(seq) == 6 and seq.n_unpaired == 0 and seq.n_missing == 0
    np.testing.assert_allclose(seq.t_s, np.arange(6) / 2.0)
    world = build_scenario("bus", 2.5, seed=4)
    truth = world.trajectory.sample(seq.t_s)
    t_gt, p_gt, q_gt = seq.groundtruth
    np.testing.assert_allclose(p_gt, truth.p_w, atol=2e-6)
    R_gt = Rotation.from_quat(q_gt).as_matrix()
    np.testing.assert_allclose(R_gt, truth.R_wc, atol=2e-6)
    frame = seq.read_frame(2)
    npz = np.load(sim_dir / "normals" / "000002.npz")
    assert frame.rgb.shape == (48, 64, 3) and frame.rgb.dtype == np.uint8
    hit = npz["kappa"] > 0
    np.testing.assert_allclose(frame.depth[hit] * DEPTH_SCALE, np.rint(frame.depth[hit] * DEPTH_SCALE))
    assert np.all(frame.depth[~hit] == 0)
    np.testing.assert_allclose(npz["R_wc"], truth.R_wc[2], atol=1e-12)
    np.testing.assert_allclose(seq.K, npz["K"])
    # The accelerometer file and the EuRoC file hold the same simulated samples.
    t_acc, acc = seq.accelerometer
    imu = read_euroc_imu(sim_dir / "imu0" / "data.csv")
    np.testing.assert_allclose(imu.t_s, t_acc, atol=1e-9)
    np.testing.assert_allclose(imu.accel_m_s2, acc, atol=1e-8)
    _, gyro, accel = simulate_imu(world.trajectory, 200.0, seed=4)
    np.testing.assert_allclose(imu.gyro_rad_s, gyro, atol=1e-9)
    assert imu.rate_hz == pytest.approx(200.0) and imu.n_non_increasing == 0


def test_same_seed_gives_identical_files_and_other_seed_differs(tmp_path, sim_dir):
    again = tmp_path / "again"
    write_sequence("bus", again, SequenceOptions(frames=6, width=64, height=48, fps=2.0, seed=4, imu_rate_hz=200.0))
    files = sorted(p.relative_to(sim_dir) for p in sim_dir.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for rel in files:
        assert (sim_dir / rel).read_bytes() == (again / rel).read_bytes(), rel
    other = tmp_path / "other"
    write_sequence("bus", other, SequenceOptions(frames=6, width=64, height=48, fps=2.0, seed=5, imu_rate_hz=200.0))
    assert (other / "scene.json").read_bytes() != (sim_dir / "scene.json").read_bytes()
    assert (other / "rgb" / "0.000000.png").read_bytes() != (sim_dir / "rgb" / "0.000000.png").read_bytes()


def test_associate_pairs_nearest_within_tolerance():
    ia, ib = associate(np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.01, 1.5, 2.005]), 0.02)
    np.testing.assert_array_equal(ia, [0, 2])
    np.testing.assert_array_equal(ib, [0, 2])


def test_associate_matches_closest_pairs_first_as_tum_does():
    """Two rgb stamps nearest the same depth stamp: the closer pair is made first and the other rgb takes
    its second-nearest depth within the tolerance (TUM associate.py), instead of going without."""
    t_rgb = np.array([0.000, 0.030])
    t_depth = np.array([0.014, 0.048])  # both rgb are nearest 0.014 (14, 16 ms); 0.030 is 18 ms from 0.048
    ia, ib = associate(t_rgb, t_depth, 0.02)
    np.testing.assert_array_equal(ia, [0, 1])
    np.testing.assert_array_equal(ib, [0, 1])
    ia, ib = associate(t_rgb, np.array([0.017]), 0.02)  # one depth, 17 and 13 ms away: the closer rgb gets it
    np.testing.assert_array_equal(ia, [1])
    np.testing.assert_array_equal(ib, [0])


def test_bad_files_raise_input_error(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_tum_rgbd(tmp_path / "nope")
    with pytest.raises(InputError, match="rgb.txt nor associations.txt"):
        load_tum_rgbd(tmp_path)
    bad = tmp_path / "data.csv"
    bad.write_text("#timestamp\n1,2,3\n")
    with pytest.raises(InputError, match="not an EuRoC IMU file"):
        read_euroc_imu(bad)


def test_reads_icl_nuim_office(shared_data):
    root = shared_data / "icl_nuim_office_kt3"
    if not root.is_dir():
        pytest.skip(f"development data not found at {root}")
    seq = load_tum_rgbd(root)
    assert len(seq) == 100 and seq.n_missing > 0  # associations list more frames than are shipped
    frame = seq.read_frame(0)
    assert frame.rgb.shape == (480, 640, 3) and frame.depth.dtype == np.float32
    assert 0.5 < np.median(frame.depth[frame.depth > 0]) < 6.0  # metres at 1/5000 m units
    t_gt, p_gt, q_gt = seq.groundtruth
    assert len(t_gt) >= 100 and q_gt.shape[1] == 4
    np.testing.assert_allclose(np.linalg.norm(q_gt, axis=1), 1.0, atol=1e-4)


def test_reads_euroc_imu(shared_data):
    path = shared_data / "euroc_v1_02_first40s" / "mav0" / "imu0" / "data.csv"
    if not path.is_file():
        pytest.skip(f"development data not found at {path}")
    imu = read_euroc_imu(path)
    assert imu.rate_hz == pytest.approx(200.0, rel=1e-3)
    assert imu.t_ns.dtype == np.int64 and imu.t_ns[0] == 1403715523912140000
    assert 9.0 < np.median(np.linalg.norm(imu.accel_m_s2, axis=1)) < 10.5
    assert imu.gyro_rad_s.mean(axis=0)[2] == pytest.approx(0.07, abs=0.03)  # the known z bias
