"""Input drivers: each source yields what its files hold, in time order, and every bad input names itself."""

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.drivers import ImuBatch, merge_imu, open_source, record
from uareme_fusion.drivers.images import ImageSource
from uareme_fusion.drivers.imu_csv import ImuCsvSource
from uareme_fusion.drivers.interleave import ImuInterleaver, split_by_span
from uareme_fusion.drivers.simulated import SimulatedSource
from uareme_fusion.drivers.tum import TumSource
from uareme_fusion.drivers.video import VideoSource, parse_webcam
from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.sim.dataset import SequenceOptions, write_sequence
from uareme_fusion.sim.imu import ImuNoise, simulate_imu
from uareme_fusion.sim.scenarios import build_scenario



def frames_of(events):
    return [e for e in events if not isinstance(e, ImuBatch)]


def imu_of(events):
    batches = [e for e in events if isinstance(e, ImuBatch)]
    return (np.concatenate([b.t_s for b in batches]), np.concatenate([b.gyro_rad_s for b in batches]),
            np.concatenate([b.accel_m_s2 for b in batches]))


def assert_time_ordered(events, offset_s=0.0):
    """IMU samples (camera time) increase, each no later than the next frame and after the previous
    one, within float rounding of the clock offset; frames increase."""
    last_frame_t, last_imu_t = -np.inf, -np.inf
    for e in events:
        if isinstance(e, ImuBatch):
            t = e.t_s + offset_s
            assert np.all(np.diff(t) > 0) and t[0] > last_imu_t and t[0] >= last_frame_t - 1e-9
            last_imu_t = t[-1]
        else:
            assert e.t_s > last_frame_t and e.t_s >= last_imu_t - 1e-9
            last_frame_t = e.t_s


def write_imu_csv(path, t_s, gyro, accel):
    t_ns = np.rint(np.asarray(t_s) * 1e9).astype(np.int64)
    with open(path, "w") as fh:
        fh.write("#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n")
        for t, g, a in zip(t_ns, gyro, accel):
            fh.write(f"{t}," + ",".join(f"{v:.17g}" for v in (*g, *a)) + "\n")


# ----- video ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def video(tmp_path_factory):
    path = tmp_path_factory.mktemp("video") / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48))
    for i in range(20):
        bgr = np.zeros((48, 64, 3), np.uint8)
        bgr[..., 0] = 200  # blue in OpenCV's BGR order
        bgr[..., 1] = 10 * i
        writer.write(bgr)
    writer.release()
    return path


def test_video_file_frames_times_and_rgb_order(video):
    with open_source(str(video)) as src:
        assert isinstance(src, VideoSource)
        assert src.info.n_frames == 20 and src.info.fps == pytest.approx(25.0)
        assert src.info.image_size == (48, 64) and not src.info.has_imu
        frames = list(src.events())
    assert [f.index for f in frames] == list(range(20))
    np.testing.assert_allclose([f.t_s for f in frames], np.arange(20) / 25.0, atol=1e-6)
    rgb = frames[7].rgb
    assert rgb.dtype == np.uint8 and rgb.shape == (48, 64, 3)
    assert abs(int(rgb[..., 2].mean()) - 200) < 6 and abs(int(rgb[..., 1].mean()) - 70) < 6 and rgb[..., 0].mean() < 6


def test_recordings_sample_frames_spread_over_them_and_leave_the_stream_as_it_is(video, tmp_path):
    """A video file and an image folder give frames spread evenly over them, first and last included,
    the same images the stream yields, and the stream still starts at frame 0."""
    for i in range(5):
        cv2.imwrite(str(tmp_path / f"{i}.png"), np.full((8, 8, 3), 40 * i, np.uint8))
    for spec, count in ((video, 20), (tmp_path, 5)):
        with open_source(str(spec)) as src:
            sampled = src.sample_frames(4)
            frames = list(src.events())
        assert [f.index for f in sampled] == ([0, 6, 13, 19] if count == 20 else [0, 1, 3, 4])
        assert len(frames) == count and frames[0].index == 0
        for f in sampled:
            np.testing.assert_array_equal(f.rgb, frames[f.index].rgb)
    with open_source(str(video)) as src:  # a run that stops at frame 10 samples its first 10 frames
        assert [f.index for f in src.sample_frames(4, limit=10)] == [0, 3, 6, 9]
    with record(ImageSource(tmp_path), tmp_path / "recorded") as src:  # recording passes them through
        assert [f.index for f in src.sample_frames(4)] == [0, 1, 3, 4]


def test_video_explicit_fps_overrides_container_clock(video):
    with open_source(str(video), fps=10.0) as src:
        times = [f.t_s for f in src.events()]
    np.testing.assert_allclose(times, np.arange(20) / 10.0)


def test_video_truncated_mid_file_raises_source_error_with_frame_index(video, tmp_path):
    data = video.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: int(len(data) * 0.8)])
    with open_source(str(cut)) as src:
        assert src.info.n_frames == 20
        with pytest.raises(SourceError, match=r"decoding stopped at frame \d+ of 20"):
            for _ in src.events():
                pass


def test_video_bad_inputs_name_the_path(tmp_path):
    bad = tmp_path / "notavideo.mp4"
    bad.write_text("hello")
    with pytest.raises(InputError, match="notavideo.mp4: neither a video .* nor an IMU table"):
        open_source(str(bad))
    bad.write_bytes(b"\x00\x01 binary, not a video")
    with pytest.raises(InputError, match="notavideo.mp4: OpenCV cannot open it"):
        open_source(str(bad))
    with pytest.raises(InputError, match="missing.mp4: no such file"):
        open_source(str(tmp_path / "missing.mp4"))


def test_webcam_spec_and_absent_camera():
    assert parse_webcam("webcam") == 0 and parse_webcam("webcam:3") == 3 and parse_webcam("web") is None
    with pytest.raises(InputError, match="webcam:57: cannot open camera 57"):
        open_source("webcam:57")


# ----- images --------------------------------------------------------------------------------
def test_image_folder_natural_order_frame_number_times_and_conversions(tmp_path):
    gray = np.full((6, 8), 90, np.uint8)
    rgba = np.zeros((6, 8, 4), np.uint8)
    rgba[..., 2] = 250  # red in BGRA
    rgba[..., 3] = 255
    deep = np.full((6, 8, 3), 65535, np.uint16)
    cv2.imwrite(str(tmp_path / "10.png"), deep)
    cv2.imwrite(str(tmp_path / "2.png"), rgba)
    cv2.imwrite(str(tmp_path / "1.png"), gray)
    (tmp_path / "notes.txt").write_text("not an image")
    with open_source(str(tmp_path)) as src:
        assert isinstance(src, ImageSource)
        frames = list(src.events())
    assert [p.name for p in src.paths] == ["1.png", "2.png", "10.png"]
    np.testing.assert_allclose([f.t_s for f in frames], np.array([1, 2, 10]) / 30.0)
    assert all(f.rgb.shape == (6, 8, 3) and f.rgb.dtype == np.uint8 for f in frames)
    assert np.all(frames[0].rgb == 90)
    assert np.all(frames[1].rgb[..., 0] == 250) and np.all(frames[1].rgb[..., 2] == 0)
    assert np.all(frames[2].rgb == 255)
    with open_source(str(tmp_path / "*.png"), fps=10.0) as src:
        np.testing.assert_allclose([f.t_s for f in src.events()], [0.0, 0.1, 0.2])


def test_image_names_in_seconds_and_nanoseconds(tmp_path):
    img = np.zeros((4, 4, 3), np.uint8)
    for name in ("1305031102.175304.png", "1305031102.211214.png"):
        cv2.imwrite(str(tmp_path / name), img)
    np.testing.assert_allclose(ImageSource(tmp_path).t_s, [1305031102.175304, 1305031102.211214])
    ns = tmp_path / "ns"
    ns.mkdir()
    for name in ("1403715273262142976.png", "1403715273312143104.png"):
        cv2.imwrite(str(ns / name), img)
    np.testing.assert_allclose(ImageSource(ns).t_s, [1403715273.262142976, 1403715273.312143104])


def test_image_bad_inputs(tmp_path):
    with pytest.raises(InputError, match="holds no image files"):
        open_source(str(tmp_path))
    with pytest.raises(InputError, match="matches no files"):
        open_source(str(tmp_path / "*.jpg"))
    (tmp_path / "a.png").write_text("not a png")
    with pytest.raises(InputError, match="a.png: not an image format OpenCV reads"):
        ImageSource(tmp_path / "*.png")
    good = tmp_path / "imgs"
    good.mkdir()
    cv2.imwrite(str(good / "0.png"), np.zeros((4, 4), np.uint8))
    data = (good / "0.png").read_bytes()
    (good / "1.png").write_bytes(data[:30])  # a valid header, truncated data
    with open_source(str(good)) as src:
        events = src.events()
        next(events)
        with pytest.raises(SourceError, match="1.png"):
            next(events)


# ----- TUM / simulate layout -------------------------------------------------------------------
R_CI = Rotation.from_euler("xyz", [90, 0, 90], degrees=True).as_matrix()


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    write_sequence("room", out, SequenceOptions(frames=6, width=32, height=24, fps=10.0, seed=2,
                                                R_ci=tuple(map(tuple, R_CI)), imu_time_offset_s=-0.013))
    return out


def test_simulate_folder_reads_fully(sim_dir):
    with open_source(str(sim_dir)) as src:
        assert isinstance(src, TumSource)
        info = src.info
        assert info.has_imu and info.has_depth and info.n_frames == 6 and info.fps == pytest.approx(10.0)
        np.testing.assert_allclose(info.R_ci, R_CI, atol=1e-12)
        assert info.imu_time_offset_s == pytest.approx(-0.013)  # t_cam = t_imu + imu_time_offset_s
        events = list(src.events())
        truth = src.ground_truth()
    assert_time_ordered(events, info.imu_time_offset_s)
    frames = frames_of(events)
    assert len(frames) == 6 and frames[0].K is not None
    npz = np.load(sim_dir / "normals" / "000003.npz")
    np.testing.assert_array_equal(frames[3].normals.normals, npz["normals"])
    np.testing.assert_array_equal(frames[3].normals.kappa, npz["kappa"])
    t, gyro, _ = imu_of(events)
    t_ref, gyro_ref, _ = simulate_imu(build_scenario("room", 0.5, 2).trajectory, 200.0, ImuNoise(), seed=2,
                                      R_ci=R_CI, imu_time_offset_s=-0.013)
    np.testing.assert_allclose(t, t_ref, atol=1e-9)
    np.testing.assert_allclose(gyro, gyro_ref, atol=1e-9)
    assert truth.gravity_aligned and truth.R_wc.shape == (6, 3, 3)
    R_ref = Rotation.from_quat(np.loadtxt(sim_dir / "groundtruth.txt")[:, 4:8]).as_matrix()
    np.testing.assert_allclose(truth.R_wc, R_ref)


def test_tum_accelerometer_only_is_exposed_not_yielded(sim_dir, tmp_path):
    for name in ("rgb.txt", "accelerometer.txt"):
        (tmp_path / name).write_text((sim_dir / name).read_text())
    (tmp_path / "rgb").symlink_to(sim_dir / "rgb")
    with open_source(str(tmp_path)) as src:
        assert not src.info.has_imu and src.info.K is None and not src.info.has_depth
        assert src.accelerometer[1].shape[1] == 3 and len(src.accelerometer[0]) > 50
        assert any("no gyro" in note for note in src.notes)
        assert not any(isinstance(e, ImuBatch) for e in src.events())
        assert src.ground_truth() is None


def test_dataset_folder_missing_index_files_says_which(tmp_path):
    (tmp_path / "rgb").mkdir()
    (tmp_path / "depth").mkdir()
    with pytest.raises(InputError, match="no index file: expected rgb.txt .* or associations.txt"):
        open_source(str(tmp_path))
    with pytest.raises(InputError, match="nothere: no such file or folder"):
        open_source(str(tmp_path / "nothere"))
    (tmp_path / "mav0" / "cam0").mkdir(parents=True)
    with pytest.raises(InputError, match="data.csv \\(the image list\\) is missing"):
        open_source(str(tmp_path))


def test_registry_rejects_unknown_options_and_fps_on_timestamped_datasets(sim_dir):
    with pytest.raises(InputError, match="unknown option\\(s\\) colour; TumSource accepts use_imu"):
        open_source(str(sim_dir), colour=True)
    with pytest.raises(InputError, match="--fps does not apply"):
        open_source(str(sim_dir), fps=5.0)
    with pytest.raises(InputError, match="sim:lobby: unknown scenario"):
        open_source("sim:lobby")


# ----- IMU CSV and merging -------------------------------------------------------------------
def test_imu_csv_source_and_wrong_columns(tmp_path):
    t = np.arange(0, 1.0, 0.005)
    gyro, accel = np.tile([0.1, 0.2, 0.3], (len(t), 1)), np.tile([0.0, 0.0, 9.81], (len(t), 1))
    write_imu_csv(tmp_path / "imu.csv", t, gyro, accel)
    with open_source(str(tmp_path / "imu.csv")) as src:
        assert isinstance(src, ImuCsvSource) and not src.info.has_frames and src.info.has_imu
        batches = list(src.events())
    assert len(batches) == 30 and all(np.ptp(b.t_s) < 1 / 30 for b in batches)
    t_all, g_all, a_all = imu_of(batches)
    np.testing.assert_allclose(t_all, t, atol=1e-9)
    np.testing.assert_array_equal(g_all, gyro)
    bad = tmp_path / "bad.csv"
    bad.write_text("#t,x,y,z\n1,0.1,0.2,0.3\n2,0.1,0.2,0.3\n")
    with pytest.raises(InputError, match="bad.csv.*7 comma-separated columns"):
        open_source(str(bad))


def test_merge_imu_interleaves_by_camera_time(video, tmp_path):
    t = np.arange(-0.5, 1.5, 0.01)
    write_imu_csv(tmp_path / "imu.csv", t, np.zeros((len(t), 3)), np.tile([0, 0, 9.81], (len(t), 1)))
    with open_source(str(video), imu=str(tmp_path / "imu.csv"), imu_time_offset_s=0.25) as src:
        assert src.info.has_imu and src.info.imu_time_offset_s == 0.25 and src.info.n_frames == 20
        events = list(src.events())
    assert_time_ordered(events, 0.25)
    first = next(i for i, e in enumerate(events) if not isinstance(e, ImuBatch))
    np.testing.assert_allclose(events[first - 1].t_s[-1] + 0.25, 0.0, atol=1e-9)  # up to the first frame
    t_all, _, _ = imu_of(events)
    np.testing.assert_allclose(t_all, t, atol=1e-9)  # stamps kept on the IMU clock, nothing lost
    with pytest.raises(InputError, match="already has an IMU"):
        merge_imu(src, ImuCsvSource(tmp_path / "imu.csv"))


def test_interleaver_pulls_lazily_and_splits_by_span():
    t = np.arange(100) * 0.01
    batches = list(split_by_span(t, np.zeros((100, 3)), np.zeros((100, 3)), 0.1))
    assert len(batches) == 10 and sum(len(b) for b in batches) == 100
    pulled = []

    def source():
        for b in batches:
            pulled.append(b)
            yield b

    imu = ImuInterleaver(source(), time_offset_s=0.05)
    first = imu.until(0.2)  # camera 0.2 = IMU 0.15
    assert first.t_s[-1] == pytest.approx(0.15) and len(pulled) == 2
    assert imu.until(0.2) is None
    rest = list(imu.rest())
    assert sum(len(b) for b in rest) + len(first) == 100


# ----- simulator and recorder ----------------------------------------------------------------
def test_simulated_normals_only_are_exact_and_imu_continuous():
    src = SimulatedSource("bus", seconds=4.5, fps=10.0, render=False, imu_noise=ImuNoise.noiseless())
    assert src.info.n_frames == 45 and src.info.image_size == (48, 64)
    events = list(src.events())
    assert_time_ordered(events)
    frames = frames_of(events)
    R_cm = src.trajectory.R_cm(np.array([f.t_s for f in frames]))
    for f, R in zip(frames[::11], R_cm[::11]):
        n = f.normals.normals.reshape(-1, 3).astype(float)
        assert f.rgb is None and np.all(f.normals.kappa > 0)
        np.testing.assert_allclose(np.abs(n @ R).max(axis=1), 1.0, atol=1e-6)  # each pixel is an axis
    t, gyro, accel = imu_of(events)  # made in 2 s chunks: equal to one uninterrupted simulation
    t_ref, gyro_ref, accel_ref = simulate_imu(src.trajectory, 200.0, ImuNoise.noiseless())
    np.testing.assert_allclose(t, t_ref, atol=1e-12)
    np.testing.assert_allclose(gyro, gyro_ref, atol=1e-12)
    np.testing.assert_allclose(accel, accel_ref, atol=1e-12)
    truth = src.ground_truth()
    np.testing.assert_allclose(truth.R_wc, src.trajectory.sample(truth.t_s).R_wc)


def test_record_then_replay_is_exact(tmp_path):
    src = SimulatedSource("dropped_frames", seconds=1.0, fps=10.0, width=32, height=24, seed=3)
    with record(src, tmp_path / "rec") as live:
        original = list(live.events())
    with open_source(str(tmp_path / "rec")) as replay:
        assert isinstance(replay, TumSource) and replay.info.has_imu
        np.testing.assert_allclose(replay.info.K, src.info.K)
        replayed = list(replay.events())
        truth = replay.ground_truth()
    assert [type(e) for e in replayed] == [type(e) for e in original]
    for a, b in zip(frames_of(original), frames_of(replayed)):
        assert a.t_s == b.t_s and a.index == b.index
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.normals.normals, b.normals.normals)
        np.testing.assert_array_equal(a.normals.kappa, b.normals.kappa)
        np.testing.assert_allclose(b.depth, a.depth, atol=0.5e-3 + 1e-5)  # millimetre PNG
    for x, y in zip(imu_of(original), imu_of(replayed)):
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-9)
    assert truth.gravity_aligned
    np.testing.assert_allclose(truth.R_wc, src.ground_truth().R_wc, atol=1e-12)
    with pytest.raises(InputError, match="folder is not empty"):
        record(src, tmp_path / "rec")


def test_interrupted_recording_replays_its_prefix(tmp_path):
    src = SimulatedSource("room", seconds=1.0, fps=10.0, render=False)
    live = record(src, tmp_path / "rec")
    events = live.events()
    seen = [next(events) for _ in range(7)]  # stopped mid-stream, never closed
    with TumSource(tmp_path / "rec") as replay:
        replayed = list(replay.events())
    assert len(frames_of(replayed)) == len(frames_of(seen))
    live.close()


# ----- real data (skipped without ../shared/data) ----------------------------------------------
def need(path: Path):
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


def test_icl_nuim_opencv_axes_keep_the_manhattan_frame_fixed(shared_data):
    from uareme_fusion.normals.depth import ICL_NUIM_K_OPENCV, DepthNormals
    from uareme_fusion.rotations import nearest_symmetric
    from uareme_fusion.solver import solve_manhattan

    src = open_source(str(need(shared_data / "icl_nuim_office_kt3")))
    assert type(src).__name__ == "IclNuimSource" and src.info.n_frames == 100
    np.testing.assert_array_equal(src.info.K, ICL_NUIM_K_OPENCV)
    truth = src.ground_truth()
    assert not truth.gravity_aligned
    R_wm = []
    for i in (0, 99):
        frame = src.read_frame(i)
        assert frame.t_s == pytest.approx((i + 1) / 30.0)
        R_wc, ok = truth.at(np.array([frame.t_s]))
        assert ok[0]
        R_wm.append(R_wc[0] @ solve_manhattan(DepthNormals().estimate_frame(frame)).R_cm)
    R_aligned, _ = nearest_symmetric(R_wm[1], R_wm[0])
    assert np.degrees(Rotation.from_matrix(R_aligned.T @ R_wm[0]).magnitude()) < 1.0


def test_euroc_imu_only_and_gravity_aligned_truth(shared_data):
    src = open_source(str(need(shared_data / "euroc_v1_02_first40s")))
    assert not src.info.has_frames and src.info.has_imu
    t, _, accel = imu_of(list(src.events()))
    truth = src.ground_truth()
    assert truth.gravity_aligned
    first_second = (t >= truth.t_s[0]) & (t < truth.t_s[0] + 1.0)  # the MAV rests on the ground
    R_wi, ok = truth.at(t[first_second])
    assert ok.all() and ok.size > 150
    up = np.einsum("nij,nj->ni", R_wi, accel[first_second]).mean(axis=0)  # at rest: +9.81 along world z
    np.testing.assert_allclose(up, [0, 0, 9.81], atol=0.4)


def test_euroc_camera_calibration_and_ground_truth(tmp_path, shared_data):
    gt = need(shared_data / "euroc_v1_02_first40s" / "mav0" / "gt0" / "data.csv")
    mav0 = tmp_path / "mav0"
    (mav0 / "cam0" / "data").mkdir(parents=True)
    (mav0 / "gt0").mkdir()
    (mav0 / "gt0" / "data.csv").write_text(gt.read_text())
    R_BS = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    T = np.eye(4)
    T[:3, :3] = R_BS
    (mav0 / "cam0" / "sensor.yaml").write_text(
        "%YAML:1.0\nT_BS:\n  cols: 4\n  rows: 4\n  data: [" + ", ".join(map(str, T.ravel())) + "]\n"
        "intrinsics: [458.6, 457.3, 16.0, 12.0]\ndistortion_coefficients: [-0.28, 0.07, 0.0002, 0.00002]\n")
    lines = ["#timestamp [ns],filename"]
    for t_ns in (1403715525000000000, 1403715525050000000):
        cv2.imwrite(str(mav0 / "cam0" / "data" / f"{t_ns}.png"), np.full((24, 32), 128, np.uint8))
        lines.append(f"{t_ns},{t_ns}.png")
    (mav0 / "cam0" / "data.csv").write_text("\n".join(lines) + "\n")
    with open_source(str(tmp_path)) as src:
        assert src.info.n_frames == 2 and not src.info.has_imu
        np.testing.assert_allclose(src.info.R_ci, R_BS.T, atol=1e-12)
        assert src.info.K[0, 0] == 458.6 and src.info.fps == pytest.approx(20.0)
        frames = list(src.events())
        truth = src.ground_truth()
    assert frames[0].t_s == pytest.approx(1403715525.0) and frames[0].rgb.shape == (24, 32, 3)
    q = np.loadtxt(gt, delimiter=",", skiprows=1, max_rows=1)[4:8]
    np.testing.assert_allclose(truth.R_wc[0], Rotation.from_quat(q, scalar_first=True).as_matrix() @ R_BS,
                               atol=1e-12)


def test_broad_is_imu_only_with_optical_truth(shared_data):
    files = sorted(need(shared_data / "broad_subset").glob("*.hdf5"))
    src = open_source(str(files[0]))
    assert not src.info.has_frames and src.info.has_imu
    batches = list(src.events())
    assert sum(len(b) for b in batches) == len(src.trial.t_s)
    truth = src.ground_truth()
    assert truth.gravity_aligned and np.all(np.isfinite(truth.R_wc))
    assert len(truth.t_s) + src.n_reference_missing == len(src.trial.t_s)
