"""ROS bags as sources: a simulated recording written with rosbags' writers (ROS 1, ROS 2 sqlite3 and
MCAP, a bare .mcap) reads back to the folder's frames, IMU and K, and runs to the folder's estimates."""

import dataclasses
import json
import shutil

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("rosbags", reason="the 'ros' extra (rosbags) is not installed")

from rosbags.rosbag1 import Writer as Ros1Writer  # noqa: E402
from rosbags.rosbag2 import Writer as Ros2Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from helpers import cli, error_lines  # noqa: E402
from uareme_fusion.drivers import open_source  # noqa: E402
from uareme_fusion.drivers.bag_tf import static_rotation  # noqa: E402
from uareme_fusion.drivers.extrinsics import with_imu_geometry  # noqa: E402
from uareme_fusion.drivers.intrinsics import CameraModel, Undistorter  # noqa: E402
from uareme_fusion.drivers.rosbag import RosbagSource  # noqa: E402
from uareme_fusion.drivers.rosbag_writer import write_bag  # noqa: E402
from uareme_fusion.errors import InputError  # noqa: E402
from uareme_fusion.formats import ros_messages as ros  # noqa: E402
from uareme_fusion.pipeline import RunConfig  # noqa: E402
from uareme_fusion.pipeline.session import run_to_folder  # noqa: E402
from uareme_fusion.sim.dataset import SequenceOptions, write_sequence  # noqa: E402
from uareme_fusion.types import Frame, ImuBatch  # noqa: E402

EPOCH_S = 1.7e9
"""Bags carry wall-clock stamps: the simulator's times plus this."""
FRAMES = 12


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "room"
    # 30 fps: at 10 fps the EKF rejected every frame of this room (ARE 75 deg), so bag and folder agreed by chance
    options = SequenceOptions(frames=FRAMES, width=64, height=48, fps=30.0, seed=1, imu_rate_hz=200.0)
    write_sequence("room", out, options)
    return out


@pytest.fixture(scope="module")
def bags(sim_dir, tmp_path_factory):
    """The recording as a ROS 1 bag (rgb8, 32FC1), a ROS 2 sqlite3 bag (bgr8, 16UC1 mm), a ROS 2
    MCAP bag (png CompressedImage, 32FC1) and that bag's .mcap file on its own."""
    root = tmp_path_factory.mktemp("bags")
    made = {}
    for name, storage, image, depth in (("ros1.bag", "ros1", "rgb8", "32FC1"), ("ros2_db3", "sqlite3", "bgr8", "16UC1"),
                                        ("ros2_mcap", "mcap", "png", "32FC1")):
        with open_source(str(sim_dir)) as src:
            write_bag(src, root / name, storage=storage, image_encoding=image, depth_encoding=depth,
                      stamp_offset_s=EPOCH_S)
        made[name] = root / name
    bare = root / "bare.mcap"
    shutil.copy(next((root / "ros2_mcap").glob("*.mcap")), bare)
    made["bare.mcap"] = bare
    return made


def _run(spec, out, **options) -> tuple[dict, np.ndarray]:
    summary = run_to_folder(str(spec), out, RunConfig(normals="depth"), evaluate=True, **options)
    return summary, np.loadtxt(out / "trajectory.tum")


@pytest.fixture(scope="module")
def folder_run(sim_dir, tmp_path_factory):
    return _run(sim_dir, tmp_path_factory.mktemp("folder_run"))


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees((Rotation.from_quat(a[:, 4:]).inv() * Rotation.from_quat(b[:, 4:])).magnitude())


@pytest.mark.parametrize("name", ["ros1.bag", "ros2_db3", "ros2_mcap", "bare.mcap"])
def test_bag_gives_the_folders_estimates_frame_by_frame(name, bags, folder_run, tmp_path):
    folder_summary, folder = folder_run
    summary, bag = _run(bags[name], tmp_path / "out")
    assert summary["stopped"] == "end" and summary["frames"] == FRAMES == len(bag) == len(folder)
    np.testing.assert_allclose(bag[:, 0] - EPOCH_S, folder[:, 0], atol=1e-6)  # header stamps, in seconds
    assert _angles_deg(bag, folder).max() < 0.5
    assert summary["source_info"]["intrinsics_from"] == f"{bags[name]} /camera/camera_info (sensor_msgs/CameraInfo)"
    assert abs(summary["are_deg"]["mean"] - folder_summary["are_deg"]["mean"]) < 0.2
    assert any("frame_id 'imu_link'" in note for note in summary["notes"])


def test_bag_reads_the_folders_frames_imu_and_K(bags, sim_dir):
    with open_source(str(sim_dir)) as folder, open_source(str(bags["ros1.bag"])) as bag:
        assert isinstance(bag, RosbagSource) and bag.info.n_frames == FRAMES and bag.info.has_imu
        np.testing.assert_array_equal(bag.info.K, folder.info.K)
        assert bag.info.K_origin.endswith("/camera/camera_info (sensor_msgs/CameraInfo)")
        ours = list(bag.events())
        theirs = list(folder.events())
    frames = [e for e in ours if isinstance(e, Frame)]
    for mine, ref in zip(frames, [e for e in theirs if isinstance(e, Frame)]):
        assert mine.t_s == pytest.approx(ref.t_s + EPOCH_S, abs=1e-6)
        np.testing.assert_array_equal(mine.rgb, ref.rgb)
        np.testing.assert_array_equal(mine.depth, ref.depth)  # 32FC1: exact metres
        np.testing.assert_array_equal(mine.K, ref.K)
    imu = ImuBatch.concat([e for e in ours if isinstance(e, ImuBatch)])
    imu_ref = ImuBatch.concat([e for e in theirs if isinstance(e, ImuBatch)])
    np.testing.assert_allclose(imu.t_s - EPOCH_S, imu_ref.t_s, atol=1e-6)
    np.testing.assert_array_equal(imu.gyro_rad_s, imu_ref.gyro_rad_s)


def test_header_stamps_are_used_not_receive_times(sim_dir, tmp_path, folder_run):
    with open_source(str(sim_dir)) as src:
        write_bag(src, tmp_path / "late.bag", image_receive_delay_s=0.35)  # images arrive 0.35 s late
    summary, bag = _run(tmp_path / "late.bag", tmp_path / "out")
    np.testing.assert_allclose(bag[:, 0], folder_run[1][:, 0], atol=1e-6)
    assert _angles_deg(bag, folder_run[1]).max() < 0.5  # as the bags frame by frame (receive times: degrees off)


def test_camera_on_another_clock_is_put_on_the_imus_by_receive_times(sim_dir, tmp_path, folder_run):
    with open_source(str(sim_dir)) as src:  # the camera's header stamps 100 s ahead; receive times agree
        write_bag(src, tmp_path / "lag.bag", image_stamp_shift_s=100.0)
    with open_source(str(tmp_path / "lag.bag")) as bag:
        assert bag.info.imu_time_offset_s == pytest.approx(100.0, abs=1e-6)
        assert any("imu_time_offset_s = 100.000000 s" in fix for fix in bag.fixes)
    summary, est = _run(tmp_path / "lag.bag", tmp_path / "out")
    assert summary["stopped"] == "end" and _angles_deg(est, folder_run[1]).max() < 0.5
    assert any("do not overlap" in fix for fix in summary["input_fixes"])


def test_clocks_that_nothing_lines_up_are_refused_naming_both_topics(sim_dir, tmp_path):
    with open_source(str(sim_dir)) as src:  # stamps and receive times both 100 s off
        write_bag(src, tmp_path / "apart.bag", image_stamp_shift_s=100.0, image_receive_delay_s=100.0)
    with open_source(str(tmp_path / "apart.bag")) as bag, pytest.raises(InputError) as err:
        list(bag.events())
    message = str(err.value)
    assert "apart.bag" in message and "/camera/image_raw" in message and "/imu/data" in message
    assert "different clocks" in message and "\n" not in message
    proc = cli("run", tmp_path / "apart.bag", "--out", tmp_path / "out", "--normals", "depth",
               "--imu-time-offset-s", "100")  # the user's offset lines them up
    assert proc.returncode == 0, proc.stderr


def _bag_with_two_cameras(path):
    """Two image, CameraInfo and IMU topics (left, right): 3 frames, 40 IMU samples each."""
    typestore = get_typestore(Stores.ROS1_NOETIC)
    types = typestore.types
    rgb = np.full((24, 32, 3), 90, np.uint8)
    with Ros1Writer(path) as bag:
        for side, fx in (("left", 30.0), ("right", 40.0)):
            conns = {k: bag.add_connection(f"/{side}/{k}", m, typestore=typestore) for k, m in
                     (("image_raw", ros.IMAGE), ("camera_info", ros.CAMERA_INFO), ("imu", ros.IMU))}
            K = np.array([[fx, 0, 15.5], [0, fx, 11.5], [0, 0, 1]])
            for k in range(40):
                t_ns = 1_000_000_000 + k * 5_000_000
                head = ros.header(types, t_ns, f"{side}_imu")
                msg = ros.imu_message(types, head, [0.0, 0.0, 0.0], [0.0, -9.81, 0.0])
                bag.write(conns["imu"], t_ns, typestore.serialize_ros1(msg, ros.IMU))
                if k % 10 == 0 and k < 30:
                    head = ros.header(types, t_ns, side)
                    for name, msg in (("image_raw", ros.image_message(types, head, rgb, "rgb8")),
                                      ("camera_info", ros.camera_info_message(types, head, K, 24, 32))):
                        bag.write(conns[name], t_ns, typestore.serialize_ros1(msg, msg.__msgtype__))
    return path


def test_several_topics_of_a_kind_are_refused_listing_them_and_chosen_by_option(tmp_path):
    path = _bag_with_two_cameras(tmp_path / "stereo.bag")
    with pytest.raises(InputError) as err:
        RosbagSource(path)
    assert str(err.value) == (f"{path}: 2 image topics: /left/image_raw (sensor_msgs/Image, 3 messages), "
                              "/right/image_raw (sensor_msgs/Image, 3 messages); choose one with --image-topic")
    with pytest.raises(InputError, match=r"2 IMU topics: /left/imu \(sensor_msgs/Imu, 40 messages\), /right/imu .*"
                                         "--imu-topic"):
        RosbagSource(path, image_topic="/right/image_raw")
    with RosbagSource(path, image_topic="/right/image_raw", imu_topic="/right/imu") as src:
        assert src.topics.camera_info == "/right/camera_info"  # the image topic's namespace
        assert src.info.K[0, 0] == 40.0 and src.info.n_frames == 3 and src.imu_frame_id == "right_imu"
    with RosbagSource(path, image_topic="/right/image_raw", imu_topic="/right/imu",
                      camera_info_topic="/left/camera_info") as src:
        assert src.info.K[0, 0] == 30.0
    with pytest.raises(InputError, match=r"--image-topic /nope: no such topic in the bag; its image topics: "):
        RosbagSource(path, image_topic="/nope")
    with pytest.raises(InputError, match=r"--imu-topic /left/image_raw: is a sensor_msgs/Image topic, not IMU"):
        RosbagSource(path, image_topic="/left/image_raw", imu_topic="/left/image_raw")


def test_cli_topic_errors_are_one_line_and_topic_options_need_a_bag(tmp_path, sim_dir):
    path = _bag_with_two_cameras(tmp_path / "stereo.bag")
    proc = cli("run", path, "--out", tmp_path / "out")
    assert proc.returncode == 2 and error_lines(proc) == [
        f"error: {path}: 2 image topics: /left/image_raw (sensor_msgs/Image, 3 messages), /right/image_raw "
        "(sensor_msgs/Image, 3 messages); choose one with --image-topic"]
    proc = cli("run", path, "--out", tmp_path / "out2", "--image-topic", "/left/image_raw", "--imu-topic", "/left/imu",
               "--normals", "depth")
    assert proc.returncode == 2 and "has none" in proc.stderr  # no depth topic: depth normals refused, one line
    proc = cli("run", sim_dir, "--out", tmp_path / "out3", "--image-topic", "/cam")
    assert proc.returncode == 2 and error_lines(proc) == [
        f"error: {sim_dir}: --image-topic applies to ROS bags and MCAP files (.bag, .mcap, .db3 or a folder with "
        "metadata.yaml), not to this source"]


def test_camera_info_distortion_is_used_as_given(tmp_path):
    typestore = get_typestore(Stores.ROS1_NOETIC)
    types = typestore.types
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    K = np.array([[50.0, 0, 31.5], [0, 52.0, 23.5], [0, 0, 1]])
    D = np.array([-0.2, 0.05, 0.001, -0.002, 0.0])
    with Ros1Writer(tmp_path / "d.bag") as bag:
        image = bag.add_connection("/cam/image_raw", ros.IMAGE, typestore=typestore)
        info = bag.add_connection("/cam/camera_info", ros.CAMERA_INFO, typestore=typestore)
        head = ros.header(types, 5_000_000_000, "cam")
        bag.write(image, 1, typestore.serialize_ros1(ros.image_message(types, head, rgb, "rgb8"), ros.IMAGE))
        msg = dataclasses.replace(ros.camera_info_message(types, head, K, 48, 64), D=D)
        bag.write(info, 1, typestore.serialize_ros1(msg, ros.CAMERA_INFO))
    with RosbagSource(tmp_path / "d.bag") as src:
        frame = next(e for e in src.events() if isinstance(e, Frame))
        assert frame.t_s == 5.0 and "/cam/camera_info (sensor_msgs/CameraInfo)" in src.info.K_origin
    expected = Undistorter(CameraModel(K, D), (48, 64)).image(rgb)
    np.testing.assert_array_equal(frame.rgb, expected)
    np.testing.assert_array_equal(frame.K, K)


@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "rgba8", "bgra8", "mono8", "mono16"])
def test_image_encodings_read_as_rgb(encoding):
    types = get_typestore(Stores.ROS2_HUMBLE).types
    rgb = np.random.default_rng(0).integers(0, 255, (5, 7, 3), dtype=np.uint8)
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    arrays = {"rgb8": rgb, "bgr8": rgb[..., ::-1], "rgba8": np.dstack([rgb, np.full((5, 7), 255, np.uint8)]),
              "bgra8": np.dstack([rgb[..., ::-1], np.zeros((5, 7), np.uint8)]), "mono8": gray,
              "mono16": gray.astype(np.uint16) * 257}
    msg = ros.image_message(types, ros.header(types, 0, "c"), arrays[encoding], encoding)
    expected = np.dstack([gray] * 3) if encoding.startswith("mono") else rgb
    np.testing.assert_array_equal(ros.image_rgb(msg, "here"), expected)


def test_depth_encodings_padded_rows_big_endian_and_refusals():
    types = get_typestore(Stores.ROS2_HUMBLE).types
    head = ros.header(types, 0, "c")
    mm = np.array([[0, 1500, 65535], [250, 1, 2]], np.uint16)
    np.testing.assert_allclose(ros.depth_metres(ros.image_message(types, head, mm, "16UC1"), "x"), mm / 1000.0)
    metres = np.array([[np.nan, 1.25, 3.0]], np.float32)
    depth = ros.depth_metres(ros.image_message(types, head, metres, "32FC1"), "x")
    np.testing.assert_array_equal(depth, [[0, 1.25, 3]])
    padded = np.zeros((2, 8), np.uint8)  # a 2x2 rgb8 image in rows of 8 bytes
    padded[:, :6] = np.arange(12).reshape(2, 6)
    msg = types[ros.IMAGE](header=head, height=2, width=2, encoding="rgb8", is_bigendian=0, step=8, data=padded.ravel())
    np.testing.assert_array_equal(ros.image_rgb(msg, "x"), np.arange(12).reshape(2, 2, 3))
    big = types[ros.IMAGE](header=head, height=1, width=2, encoding="16UC1", is_bigendian=1, step=4,
                           data=np.array([0x03, 0xE8, 0x07, 0xD0], np.uint8))  # 1000, 2000 mm big-endian
    np.testing.assert_allclose(ros.depth_metres(big, "x"), [[1.0, 2.0]])
    with pytest.raises(InputError, match=r"^here: image encoding 'yuv422' is not supported"):
        ros.image_rgb(types[ros.IMAGE](header=head, height=1, width=1, encoding="yuv422", is_bigendian=0, step=2,
                                       data=np.zeros(2, np.uint8)), "here")
    with pytest.raises(InputError, match="the message is inconsistent"):
        ros.image_rgb(types[ros.IMAGE](header=head, height=4, width=4, encoding="rgb8", is_bigendian=0, step=12,
                                       data=np.zeros(10, np.uint8)), "here")


def test_ground_truth_and_eval_from_a_pose_topic(bags, folder_run, tmp_path):
    with open_source(str(bags["ros2_mcap"])) as bag:
        truth = bag.ground_truth()
        assert truth.gravity_aligned  # frame_id "world": z up by ROS convention
        assert len(truth.t_s) == FRAMES and truth.t_s[0] == pytest.approx(EPOCH_S)
    proc = cli("eval", bags["ros1.bag"], "--out", tmp_path / "eval", "--normals", "depth")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "eval" / "summary.json").read_text())
    assert summary["are_deg"]["mean"] == pytest.approx(folder_run[0]["are_deg"]["mean"], abs=0.2)


def test_imu_only_bag_and_unreadable_files(tmp_path):
    typestore = get_typestore(Stores.ROS1_NOETIC)
    with Ros1Writer(tmp_path / "only_imu.bag") as bag:
        conn = bag.add_connection("/imu", ros.IMU, typestore=typestore)
        for k in range(400):
            head = ros.header(typestore.types, 10**9 + k * 5_000_000, "imu")
            msg = ros.imu_message(typestore.types, head, [0.0, 0.1, 0.0], [0.0, 0.0, 9.81])
            bag.write(conn, 10**9 + k * 5_000_000, typestore.serialize_ros1(msg, ros.IMU))
    with open_source(str(tmp_path / "only_imu.bag")) as src:
        assert not src.info.has_frames and src.info.has_imu
        assert sum(len(e) for e in src.events()) == 400
    (tmp_path / "junk.bag").write_bytes(b"not a bag at all" * 10)
    proc = cli("run", tmp_path / "junk.bag", "--out", tmp_path / "out")
    assert proc.returncode == 2 and len(error_lines(proc)) == 1
    assert error_lines(proc)[0].startswith(f"error: {tmp_path / 'junk.bag'}: not a ROS bag rosbags can read")


def test_camera_imu_rotation_from_tf_static(sim_dir, tmp_path):
    R_ci = Rotation.from_euler("xyz", [90, 0, -90], degrees=True).as_matrix()  # an IMU mounted x forward, z up
    with with_imu_geometry(open_source(str(sim_dir)), R_ci=R_ci) as src:
        write_bag(src, tmp_path / "tf.bag")
    with open_source(str(tmp_path / "tf.bag")) as bag:
        np.testing.assert_allclose(bag.info.R_ci, R_ci, atol=1e-12)
        assert any("from /tf_static, 'camera_optical' <- 'imu_link'" in note for note in bag.notes)
        truth = bag.ground_truth()  # poses of the IMU body, R_wc = R_wb R_ci^T: the simulator's camera again
    with open_source(str(sim_dir)) as folder:
        np.testing.assert_allclose(truth.R_wc, folder.ground_truth().R_wc, atol=1e-9)
    path = _bag_with_two_cameras(tmp_path / "stereo.bag")
    with RosbagSource(path, image_topic="/left/image_raw", imu_topic="/left/imu") as src:
        np.testing.assert_array_equal(src.info.R_ci, np.eye(3))
        assert any("identity: no /tf_static chain joins the camera's frame_id 'left' and the IMU's 'left_imu'" in n
                   for n in src.notes)


def test_static_transform_chains_compose(tmp_path):
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    types = typestore.types
    R_cb = Rotation.from_euler("z", 30, degrees=True)  # base in camera
    R_ib = Rotation.from_euler("x", 20, degrees=True)  # base in IMU: the chain runs camera -> base <- imu
    with Ros2Writer(tmp_path / "chain", version=9) as bag:
        conn = bag.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=typestore)
        transforms = []
        for parent, child, R in (("camera", "base_link", R_cb), ("/imu", "base_link", R_ib)):
            x, y, z, w = R.as_quat()
            transforms.append(types["geometry_msgs/msg/TransformStamped"](
                header=ros.header(types, 0, parent), child_frame_id=child,
                transform=types["geometry_msgs/msg/Transform"](
                    translation=types["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0),
                    rotation=types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w))))
        msg = types["tf2_msgs/msg/TFMessage"](transforms=transforms)
        bag.write(conn, 1, typestore.serialize_cdr(msg, msg.__msgtype__))
    from rosbags.highlevel import AnyReader

    with AnyReader([tmp_path / "chain"]) as reader:
        R_ci = static_rotation(reader, "camera", "imu")
        assert static_rotation(reader, "camera", "lidar") is None
    np.testing.assert_allclose(R_ci, (R_cb * R_ib.inv()).as_matrix(), atol=1e-12)


def test_intrinsics_option_replaces_the_camera_info(bags, sim_dir):
    with open_source(str(bags["ros1.bag"]), intrinsics="40,41,31.5,23.5") as bag:
        np.testing.assert_array_equal(bag.info.K, [[40, 0, 31.5], [0, 41, 23.5], [0, 0, 1]])
        assert bag.info.K_origin == "--intrinsics 40,41,31.5,23.5"
        assert any("replaces the bag's /camera/camera_info" in note for note in bag.notes)
        frame = next(e for e in bag.events() if isinstance(e, Frame))
    with open_source(str(sim_dir)) as folder:
        np.testing.assert_array_equal(frame.rgb, next(e for e in folder.events() if isinstance(e, Frame)).rgb)


@pytest.mark.slow
def test_horizon_ground_and_compare_take_a_bag(bags, tmp_path):
    proc = cli("horizon", bags["ros1.bag"], "--out", tmp_path / "h.mp4", "--normals", "depth")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "h.mp4").stat().st_size > 0
    proc = cli("ground", bags["bare.mcap"], "--out", tmp_path / "g", "--normals", "depth")
    assert proc.returncode == 0, proc.stderr
    assert len(list((tmp_path / "g" / "masks").iterdir())) == FRAMES
    proc = cli("compare", bags["ros2_db3"], "--out", tmp_path / "c", "--normals", "depth", "--gt-topic",
               "/ground_truth/pose")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "c" / "compare.json").read_text())
    assert len(doc["backends"]) >= 3


@pytest.mark.parametrize("store", ["ros1", "ros2"])
def test_raw_header_stamps_match_deserialised_ones(store):
    typestore = get_typestore(Stores.ROS1_NOETIC if store == "ros1" else Stores.ROS2_HUMBLE)
    types = typestore.types
    t_ns = 1_700_000_123_456_789_012
    for msg in (ros.image_message(types, ros.header(types, t_ns, "camera"), np.zeros((2, 3), np.uint8), "mono8"),
                ros.compressed_message(types, ros.header(types, t_ns, "c"), np.zeros((4, 4, 3), np.uint8), "png")):
        if store == "ros1":
            raw = typestore.serialize_ros1(msg, msg.__msgtype__)
        else:
            raw = typestore.serialize_cdr(msg, msg.__msgtype__)
            big = typestore.serialize_cdr(msg, msg.__msgtype__, little_endian=False)
            assert ros.raw_stamp_ns(big, cdr=True) == t_ns
        assert ros.raw_stamp_ns(raw, cdr=store == "ros2") == t_ns == ros.stamp_ns(msg.header)


def test_odometry_ground_truth_in_a_frame_that_is_not_z_up(tmp_path):
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    types = typestore.types
    R_wb = Rotation.from_euler("zyx", [40, 10, -5], degrees=True)
    with Ros2Writer(tmp_path / "odom", version=9) as bag:
        imu = bag.add_connection("/imu", ros.IMU, typestore=typestore)
        odom = bag.add_connection("/vicon/odom", ros.ODOMETRY, typestore=typestore)
        for k in range(300):
            t_ns = 2 * 10**9 + k * 5_000_000
            msg = ros.imu_message(types, ros.header(types, t_ns, "imu"), [0.0, 0.0, 0.0], [0.0, 0.0, 9.81])
            bag.write(imu, t_ns, typestore.serialize_cdr(msg, ros.IMU))
            if k % 10 == 0:
                pose = ros.pose_message(types, ros.header(types, t_ns, "vicon"), R_wb.as_quat()).pose
                cov = types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
                twist = types["geometry_msgs/msg/TwistWithCovariance"](
                    twist=types["geometry_msgs/msg/Twist"](linear=types["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0),
                                                           angular=types["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)),
                    covariance=np.zeros(36))
                msg = types[ros.ODOMETRY](header=ros.header(types, t_ns, "vicon"), child_frame_id="body", pose=cov,
                                          twist=twist)
                bag.write(odom, t_ns, typestore.serialize_cdr(msg, ros.ODOMETRY))
    with open_source(str(tmp_path / "odom")) as src:
        assert not src.info.has_frames
        truth = src.ground_truth()
    assert len(truth.t_s) == 30 and truth.t_s[0] == 2.0 and not truth.gravity_aligned  # "vicon": no convention
    np.testing.assert_allclose(truth.R_wc, np.repeat(R_wb.as_matrix()[None], 30, axis=0), atol=1e-12)
