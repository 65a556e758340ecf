"""OAK driver without hardware: message conversion, frame/IMU sync and recording with fake depthai
messages; the hardware test runs only with a device attached (`-m hardware`)."""

import sys

import numpy as np
import pytest

from uareme_fusion.drivers import ImuBatch, Recorder, SourceInfo, open_source
from uareme_fusion.drivers.oak import (FrameImuSync, ImuConversionCounts, batch_from_packets, frame_from_messages,
                                       import_depthai, rotation_from_extrinsics)
from uareme_fusion.drivers.tum import TumSource
from uareme_fusion.errors import InputError, SourceError

from helpers import FakeImgFrame, packets  # pytest puts tests/ on sys.path


def fake_rgb(t_s, seed, size=(8, 12)):
    bgr = np.random.default_rng(seed).integers(0, 256, (*size, 3), dtype=np.uint8)
    return FakeImgFrame(bgr, t_s)


def test_frame_conversion_rgb_order_depth_units_and_device_time():
    rgb_msg = fake_rgb(12.345678, seed=1)
    depth_mm = np.array([[0, 1000, 65535] * 4] * 8, np.uint16)
    K = np.array([[500.0, 0, 6], [0, 500, 4], [0, 0, 1]])
    frame = frame_from_messages(rgb_msg, 7, K, FakeImgFrame(depth_mm, 12.345678))
    assert frame.t_s == pytest.approx(12.345678, abs=1e-6) and frame.index == 7 and frame.K is K
    np.testing.assert_array_equal(frame.rgb, rgb_msg.image[..., ::-1])
    assert frame.depth.dtype == np.float32
    np.testing.assert_allclose(frame.depth[0, :3], [0.0, 1.0, 65.535], rtol=1e-6)
    with pytest.raises(SourceError, match="not aligned to RGB"):
        frame_from_messages(rgb_msg, 0, K, FakeImgFrame(np.zeros((4, 6), np.uint16), 12.3))


def test_imu_conversion_units_gyro_times_and_repeated_stamps():
    pk = packets([1.000, 1.005, 1.005, 1.010])  # the third repeats the gyro stamp (accel-only update)
    counts = ImuConversionCounts()
    batch = batch_from_packets(pk, counts, last_t_s=-np.inf)
    np.testing.assert_allclose(batch.t_s, [1.000, 1.005, 1.010])
    np.testing.assert_allclose(batch.gyro_rad_s[1], [pk[1].gyroscope.x, pk[1].gyroscope.y, pk[1].gyroscope.z])
    np.testing.assert_allclose(batch.accel_m_s2[2], [pk[3].acceleroMeter.x, pk[3].acceleroMeter.y,
                                                     pk[3].acceleroMeter.z])
    assert counts.repeated == 1
    again = batch_from_packets(packets([1.010, 1.015]), counts, last_t_s=1.010)  # overlap with the last batch
    np.testing.assert_allclose(again.t_s, [1.015])
    assert counts.repeated == 2 and len(batch_from_packets([], counts)) == 0


def test_extrinsics_to_R_ci():
    from scipy.spatial.transform import Rotation

    R = Rotation.from_euler("xyz", [180, 0, 90], degrees=True).as_matrix()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [2.1, -0.5, 0.3]  # centimetres
    np.testing.assert_allclose(rotation_from_extrinsics(T.tolist()), R, atol=1e-12)
    with pytest.raises(InputError, match="hold no rotation"):
        rotation_from_extrinsics(np.zeros((4, 4)))
    with pytest.raises(InputError, match="4x4"):
        rotation_from_extrinsics(np.eye(3))


def test_sync_releases_frames_after_the_imu_passes_them():
    sync = FrameImuSync(use_imu=True, max_pending_frames=2)
    out = []
    out += sync.push_imu(batch_from_packets(packets(np.arange(6) * 0.005)))  # IMU up to 0.025
    out += sync.push_frame(frame_from_messages(fake_rgb(0.033, 1), 0))
    assert out == [] or all(isinstance(e, ImuBatch) for e in out)  # frame held: IMU not yet at 0.033
    out += sync.push_imu(batch_from_packets(packets(np.arange(6, 14) * 0.005, 1)))
    kinds = ["F" if not isinstance(e, ImuBatch) else "I" for e in out]
    assert kinds == ["I", "F"]
    assert out[0].t_s[-1] == pytest.approx(0.030) and out[0].t_s[0] == 0.0  # all samples <= frame time
    # IMU stalls: frames are released once more than max_pending_frames wait.
    out = []
    for i, t in enumerate((0.066, 0.100, 0.133)):
        out += sync.push_frame(frame_from_messages(fake_rgb(t, i), i + 1))
    assert [type(e).__name__ for e in out] == ["ImuBatch", "Frame"]
    assert out[0].t_s[-1] == pytest.approx(0.065) and out[1].t_s == 0.066
    # Late IMU (older than a released frame) is dropped and counted, never reordered.
    out = sync.push_imu(ImuBatch(np.array([0.060, 0.110]), np.zeros((2, 3)), np.zeros((2, 3))))
    assert sync.late_imu == 1
    tail = out + sync.flush()
    assert [type(e).__name__ for e in tail] == ["Frame", "ImuBatch", "Frame"]
    assert tail[1].t_s.tolist() == [0.110]


def test_sync_without_imu_passes_frames_through():
    sync = FrameImuSync(use_imu=False)
    frame = frame_from_messages(fake_rgb(1.0, 0), 0)
    assert sync.push_frame(frame) == [frame] and sync.flush() == []


def test_recording_of_a_fake_session_replays_exactly(tmp_path):
    sync = FrameImuSync()
    K = np.array([[400.0, 0, 5.5], [0, 400, 3.5], [0, 0, 1]])
    R_ci = np.array([[0.0, -1, 0], [-1, 0, 0], [0, 0, -1]])
    info = SourceInfo(name="oak", K=K, has_imu=True, has_depth=True, R_ci=R_ci, fps=30.0)
    recorder = Recorder(tmp_path / "session", info)
    stream = []
    t0 = 1234.567891234  # device clock, seconds since boot
    for i in range(5):
        t_frame = t0 + i / 30.0
        depth = np.random.default_rng(i).integers(0, 5000, (8, 12), dtype=np.uint16)
        stream += sync.push_imu(batch_from_packets(packets(t_frame - 1 / 30 + np.arange(1, 7) / 200.0, i)))
        stream += sync.push_frame(frame_from_messages(fake_rgb(t_frame, i), i, K, FakeImgFrame(depth, t_frame)))
    stream += sync.flush()
    for event in stream:
        recorder.write(event)
    recorder.close()
    with TumSource(tmp_path / "session") as replay:
        np.testing.assert_allclose(replay.info.R_ci, R_ci)
        np.testing.assert_allclose(replay.info.K, K)
        replayed = list(replay.events())
    assert [type(e) for e in replayed] == [type(e) for e in stream]
    for a, b in zip(stream, replayed):
        if isinstance(a, ImuBatch):
            np.testing.assert_allclose(b.t_s, a.t_s, rtol=0, atol=1e-9)
            np.testing.assert_array_equal(b.gyro_rad_s, a.gyro_rad_s)
            np.testing.assert_array_equal(b.accel_m_s2, a.accel_m_s2)
        else:
            assert b.t_s == a.t_s
            np.testing.assert_array_equal(b.rgb, a.rgb)
            np.testing.assert_array_equal(b.depth, a.depth)  # millimetres are stored exactly


def test_without_depthai_the_message_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "depthai", None)
    with pytest.raises(InputError, match=r"install uareme-fusion\[oak\]"):
        import_depthai()
    with pytest.raises(InputError, match=r"install uareme-fusion\[oak\]"):
        open_source("oak")


@pytest.mark.hardware
def test_live_oak_device_streams_frames_and_imu():
    dai = pytest.importorskip("depthai", reason="depthai not installed")
    if not dai.Device.getAllAvailableDevices():
        pytest.skip("no OAK device connected")
    with open_source("oak") as src:
        events = src.events()
        seen = [next(events) for _ in range(40)]
    frames = [e for e in seen if not isinstance(e, ImuBatch)]
    assert frames and frames[0].rgb.shape[:2] == src.info.image_size and src.info.K is not None
    assert np.all(np.diff([f.t_s for f in frames]) > 0)
