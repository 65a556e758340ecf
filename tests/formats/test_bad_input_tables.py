"""Bad input for the text and HDF5 readers: EuRoC IMU CSV, TUM lists, trajectories, accelerometer and
associations files, TUM RGB-D folders, BROAD trials.

Each case asserts an `InputError` naming the file and the line (and column where one cell is at
fault), or the documented recovery with its count (IMU timestamps out of order are kept and counted
by the reader, then reordered, dropped and counted by the filter's IMU stream; jumps become gaps).
"""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from uareme_fusion.backends.mekf import Mekf, MekfConfig
from uareme_fusion.formats.broad import read_broad
from uareme_fusion.formats.euroc import read_euroc_imu
from uareme_fusion.formats.tum import (
    load_tum_rgbd,
    read_associations,
    read_tum_accelerometer,
    read_tum_list,
    read_tum_trajectory,
)
from uareme_fusion.errors import InputError
from uareme_fusion.types import Status

HEADER = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y,w_RS_S_z,a_RS_S_x [m s^-2],a_RS_S_y,a_RS_S_z\n"


def euroc_rows(n=5, t0_ns=1_000_000_000, step_ns=5_000_000):
    return "".join(f"{t0_ns + i * step_ns},0.01,0.02,0.03,0.0,-9.81,0.0\n" for i in range(n))


GOOD = HEADER + euroc_rows()

# (case id, file content, regex the message must match); the message must also name the file.
EUROC_CASES = [
    ("empty_file", "", "holds no IMU samples"),
    ("header_only", HEADER, "holds no IMU samples"),
    ("comments_and_blank_lines", "# a\n\n# b\n   \n", "holds no IMU samples"),
    ("six_columns", HEADER + "1000,0.1,0.2,0.3,0,0\n", "not an EuRoC IMU file: line 2 has 6 column"),
    ("three_columns", "#timestamp\n1,2,3\n", "not an EuRoC IMU file: line 2 has 3 column"),
    ("one_column", HEADER + "1000\n2000\n", "line 2 has 1 column"),
    ("ragged_row", GOOD + "1030000000,0.1,0.2\n", "line 7 has 3 column.*line 2 has 7"),
    ("ragged_after_blank_lines", HEADER + "\n\n" + euroc_rows(2) + "1,2\n", "line 6 has 2 column"),
    ("semicolons", HEADER + euroc_rows().replace(",", ";"), "line 2 has 1 column"),
    ("tabs", HEADER + euroc_rows().replace(",", "\t"), "line 2 has 1 column"),
    ("spaces", HEADER + euroc_rows().replace(",", " "), "line 2 has 1 column"),
    ("text_header_without_hash", "timestamp,wx,wy,wz,ax,ay,az\n" + euroc_rows(),
     r"line 1, column 1 \(timestamp \[ns\]\): cannot read 'timestamp' as an integer"),
    ("text_in_gyro", GOOD + "1030000000,0.1,abc,0.3,0,0,9.81\n",
     r"line 7, column 3 \(w_y \[rad/s\]\): cannot read 'abc'"),
    ("text_in_accel", GOOD + "1030000000,0.1,0.2,0.3,0,0,g\n", r"line 7, column 7 \(a_z \[m/s\^2\]\)"),
    ("empty_cell", GOOD + "1030000000,0.1,,0.3,0,0,9.81\n", r"line 7, column 3 .*cannot read ''"),
    ("float_timestamp", HEADER + "1.5e9,0.1,0.2,0.3,0,0,9.81\n", r"line 2, column 1 .*'1.5e9' as an integer"),
    ("decimal_timestamp", HEADER + "1403636579.758,0.1,0.2,0.3,0,0,9.81\n", r"line 2, column 1 .*as an integer"),
    ("overflowing_timestamp", HEADER + "99999999999999999999,0.1,0.2,0.3,0,0,9.81\n",
     r"line 2, column 1 .*as an integer"),
    ("nan_timestamp", HEADER + "nan,0.1,0.2,0.3,0,0,9.81\n", r"line 2, column 1 .*'nan' as an integer"),
    ("nan_gyro", GOOD + "1030000000,nan,0.2,0.3,0,0,9.81\n",
     r"1 row\(s\) hold a NaN or infinite gyro or accel value \(line 7\)"),
    ("inf_accel", GOOD + "1030000000,0.1,0.2,0.3,0,inf,9.81\n", r"NaN or infinite .*\(line 7\)"),
    ("minus_inf", GOOD + "1030000000,0.1,0.2,0.3,0,-inf,9.81\n", r"\(line 7\)"),
    ("many_nans", HEADER + euroc_rows(6).replace("0.02", "nan"),
     r"6 row\(s\) .*lines 2, 3, 4 and 3 more"),
    ("binary_garbage", bytes(range(256)) * 4, "not a text file"),
    ("utf16", GOOD.encode("utf-16"), "not a text file"),
    ("folder_without_data_csv", "FOLDER", "does not exist"),
    ("missing_file", "MISSING", "does not exist"),
]


def write_case(tmp_path, content, name="data.csv"):
    path = tmp_path / name
    if isinstance(content, str) and content == "FOLDER":
        (tmp_path / "imu_folder").mkdir()
        return tmp_path / "imu_folder"
    if isinstance(content, str) and content == "MISSING":
        return path
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


@pytest.mark.parametrize("case, content, message", EUROC_CASES, ids=[c[0] for c in EUROC_CASES])
def test_bad_euroc_files_name_the_file_line_and_column(tmp_path, case, content, message):
    path = write_case(tmp_path, content)
    with pytest.raises(InputError) as info:
        read_euroc_imu(path)
    assert str(path) in str(info.value) and re.search(message, str(info.value)), str(info.value)


@pytest.mark.parametrize(
    "case, content, n_rows",
    [("no_header", euroc_rows(), 5), ("utf8_bom", "\ufeff" + GOOD, 5), ("crlf", GOOD.replace("\n", "\r\n"), 5),
     ("blank_lines_between", GOOD.replace("\n", "\n\n"), 5),
     ("extra_columns_ignored", HEADER + "1,0,0,0,0,0,9.8,25.0\n", 1),
     ("spaces_after_commas", HEADER + "1, 0.1, 0.2, 0.3, 0, 0, 9.8\n", 1), ("no_final_newline", GOOD.rstrip("\n"), 5)],
    ids=lambda v: v if isinstance(v, str) and len(v) < 30 else "",
)
def test_tolerated_euroc_variants_read_every_row(tmp_path, case, content, n_rows):
    imu = read_euroc_imu(write_case(tmp_path, content))
    assert len(imu.t_ns) == n_rows and imu.gyro_rad_s.shape == (n_rows, 3) and imu.t_ns.dtype == np.int64
    assert np.all(np.isfinite(imu.accel_m_s2))


def test_euroc_folder_layouts_find_data_csv(tmp_path):
    (tmp_path / "mav0" / "imu0").mkdir(parents=True)
    (tmp_path / "mav0" / "imu0" / "data.csv").write_text(GOOD)
    assert len(read_euroc_imu(tmp_path).t_ns) == 5
    assert len(read_euroc_imu(tmp_path / "mav0").t_ns) == 5


TIMESTAMP_CASES = [  # (id, timestamps in ns, expected n_non_increasing)
    ("duplicated", [0, 5, 10, 10, 15, 20], 1),
    ("step_back", [0, 5, 10, 7, 15, 20], 1),
    ("reversed", [25, 20, 15, 10, 5, 0], 5),
    ("all_equal", [5, 5, 5, 5], 3),
    ("jump_forward", [0, 5, 10, 5_000_000_000, 5_000_000_005], 0),
]


@pytest.mark.parametrize("case, stamps_ms, n_bad", TIMESTAMP_CASES, ids=[c[0] for c in TIMESTAMP_CASES])
def test_euroc_timestamps_out_of_order_are_kept_and_counted(tmp_path, case, stamps_ms, n_bad):
    rows = "".join(f"{1_000_000_000 + 1_000_000 * t},0,0,0,0,-9.81,0\n" for t in stamps_ms)
    imu = read_euroc_imu(write_case(tmp_path, HEADER + rows))
    assert len(imu.t_ns) == len(stamps_ms)  # nothing dropped by the reader
    assert imu.n_non_increasing == n_bad


def test_euroc_duplicates_and_steps_back_are_counted_by_the_filter(tmp_path):
    t_ms = [0, 5, 10, 10, 15, 20, 12, 25, 30]  # one duplicate, one 8 ms step back (< 20 ms reorder window)
    rows = "".join(f"{1_000_000_000 + 1_000_000 * t},0,0,0,0,-9.81,0\n" for t in t_ms)
    imu = read_euroc_imu(write_case(tmp_path, HEADER + rows))
    filt = Mekf(MekfConfig(mode="imu_only"))
    filt.process_imu(imu.t_s, imu.gyro_rad_s, imu.accel_m_s2)
    est = filt.process_frame(imu.t_s.max() + 0.05, None)
    counts = filt.stream.counts
    assert counts.duplicate == 1 and counts.late == 0
    assert np.all(np.isfinite(est.R_wc)) and np.all(np.isfinite(est.cov))


def test_euroc_jump_in_time_becomes_a_flagged_gap(tmp_path):
    t_s = np.r_[np.arange(0, 0.5, 0.005), 3.0 + np.arange(0, 0.1, 0.005)]
    rows = "".join(f"{int(round(1e9 + t * 1e9))},0,0,0,0,-9.81,0\n" for t in t_s)
    imu = read_euroc_imu(write_case(tmp_path, HEADER + rows))
    assert imu.n_non_increasing == 0 and len(imu.t_ns) == len(t_s)
    filt = Mekf(MekfConfig(mode="imu_only"))
    filt.process_imu(imu.t_s[:100], imu.gyro_rad_s[:100], imu.accel_m_s2[:100])
    before = filt.process_frame(imu.t_s[99], None)
    filt.process_imu(imu.t_s[100:], imu.gyro_rad_s[100:], imu.accel_m_s2[100:])
    after = filt.process_frame(imu.t_s[-1], None)
    assert Status.IMU_GAP in after.status and Status.IMU_GAP not in before.status
    assert np.trace(after.cov) > np.trace(before.cov)


# ---------------------------------------------------------------- TUM text files

LIST_CASES = [
    ("one_column", "1.0\n2.0\n", r"not a TUM image list: line 1 has 1 column"),
    ("ragged", "1.0 rgb/1.png\n2.0\n", r"line 2 has 1 column.*line 1 has 2"),
    ("text_timestamp", "# c\nabc rgb/1.png\n", r"line 2, column 1 \(timestamp \[s\]\): cannot read 'abc' as a number"),
    ("nan_timestamp", "1.0 a.png\nnan b.png\n", r"NaN or infinite timestamp \(line 2\)"),
    ("inf_timestamp", "inf a.png\n", r"NaN or infinite timestamp \(line 1\)"),
    ("duplicate_timestamp", "1.0 a.png\n1.0 b.png\n",
     r"line 2: timestamp 1.0 is not after the previous row's 1.0 \(line 1\)"),
    ("not_sorted", "# h\n1.0 a.png\n3.0 b.png\n2.0 c.png\n", r"line 4: timestamp 2.0 is not after.*3.0 \(line 3\)"),
    ("binary", b"\xff\xfe\x00\x01" * 10, "not a text file"),
]

TRAJECTORY_CASES = [
    ("seven_columns", "1 0 0 0 0 0 0\n", r"not a TUM trajectory file: line 1 has 7 column"),
    ("text_cell", "1 0 0 0 a 0 0 1\n", r"line 1, column 5 \(qx\): cannot read 'a'"),
    ("nan_position", "1 nan 0 0 0 0 0 1\n", r"NaN or infinite value \(line 1\)"),
    ("nan_quaternion", "# x\n1 0 0 0 0 0 0 1\n2 0 0 0 nan 0 0 1\n", r"\(line 3\)"),
    ("zero_quaternion", "1 0 0 0 0 0 0 0\n2 0 0 0 0 0 0 1\n",
     r"1 quaternion\(s\) .*not unit length \(line 1; first norm 0\)"),
    ("unnormalised_quaternion", "1 0 0 0 0 0 0 2\n", r"not unit length \(line 1; first norm 2\)"),
    ("not_sorted", "2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", r"line 2: timestamp 1 is not after .*2 \(line 1\)"),
    ("duplicate", "1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", r"line 2: timestamp 1 is not after"),
    ("wxyz_order_with_extra_column", "1 0 0 0 1 0 0 0 9\n2 0 0 0 1 0 0 0\n", r"line 2 has 8 column.*line 1 has 9"),
]

ACCELEROMETER_CASES = [
    ("three_columns", "1 0 0\n", r"not a TUM accelerometer file: line 1 has 3 column"),
    ("nan", "1 0 0 nan\n", r"NaN or infinite value \(line 1\)"),
    ("inf_time", "inf 0 0 9.8\n", r"\(line 1\)"),
    ("ragged", "1 0 0 9.81\n2 0 0\n", "line 2 has 3 column"),
    ("text", "1 0 0 nine\n", r"line 1, column 4 \(az \[m/s\^2\]\)"),
]

ASSOCIATION_CASES = [
    ("two_columns", "1.0 rgb/a.png\n", "not a TUM associations file: line 1 has 2 column"),
    ("three_columns", "1.0 rgb/a.png 1.0\n", "line 1 has 3 column"),
    ("text_time", "x rgb/a.png 1.0 depth/a.png\n", r"line 1, column 1 .*cannot read 'x'"),
    ("not_sorted", "2 rgb/a.png 2 depth/a.png\n1 rgb/b.png 1 depth/b.png\n", "line 2: timestamp 1 is not after"),
    ("depth_first_nan_rgb_time", "1 depth/a.png nan rgb/a.png\n", r"NaN or infinite timestamp \(line 1\)"),
]


def _read_cases(reader, cases):
    return [pytest.param(reader, content, message, id=f"{reader.__name__}-{case}") for case, content, message in cases]


@pytest.mark.parametrize(
    "reader, content, message",
    _read_cases(read_tum_list, LIST_CASES) + _read_cases(read_tum_trajectory, TRAJECTORY_CASES)
    + _read_cases(read_tum_accelerometer, ACCELEROMETER_CASES) + _read_cases(read_associations, ASSOCIATION_CASES),
)
def test_bad_tum_text_files_name_the_file_and_line(tmp_path, reader, content, message):
    path = write_case(tmp_path, content, "file.txt")
    with pytest.raises(InputError) as info:
        reader(path)
    assert str(path) in str(info.value) and re.search(message, str(info.value)), str(info.value)


def test_tum_trajectory_renormalises_rounded_quaternions(tmp_path):
    path = write_case(tmp_path, "1 0 0 0 0 0 0.7071 0.7071\n2 0 0 0 0 0 0 1.004\n", "gt.txt")
    _, _, q = read_tum_trajectory(path)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)


def test_empty_tum_files_give_empty_arrays(tmp_path):
    path = write_case(tmp_path, "# only a comment\n\n", "empty.txt")
    assert len(read_tum_list(path)[0]) == 0 and read_tum_trajectory(path)[2].shape == (0, 4)
    assert read_tum_accelerometer(path)[1].shape == (0, 3)


# ---------------------------------------------------------------- TUM RGB-D folders


def tum_folder(root, n=3, rgb=None, depth=None, extra=None):
    """A tiny TUM RGB-D folder: n frames 8x10, rgb.txt and depth.txt, with overrides per file."""
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    for i in range(n):
        cv2.imwrite(str(root / "rgb" / f"{i}.png"), np.full((8, 10, 3), 100, np.uint8))
        cv2.imwrite(str(root / "depth" / f"{i}.png"), np.full((8, 10), 5000, np.uint16))
    default = {kind: "".join(f"{i * 0.1:.1f} {kind}/{i}.png\n" for i in range(n)) for kind in ("rgb", "depth")}
    (root / "rgb.txt").write_text(rgb if rgb is not None else default["rgb"])
    (root / "depth.txt").write_text(depth if depth is not None else default["depth"])
    for name, content in (extra or {}).items():
        write_case(root, content, name)
    return root


FOLDER_CASES = [
    ("scene_json_not_json", {"scene.json": "{not json"}, {}, r"scene.json: not a readable JSON file"),
    ("scene_json_list", {"scene.json": "[1, 2]"}, {}, "expected a JSON object, got list"),
    ("scene_json_zero_scale", {"scene.json": '{"depth_scale": 0}'}, {}, "depth_scale must be a positive number, got 0"),
    ("scene_json_text_scale", {"scene.json": '{"depth_scale": "5000"}'}, {}, "depth_scale must be a positive number"),
    ("scene_json_bad_K", {"scene.json": '{"K": [[1, 0], [0, 1]]}'}, {}, "K must be a 3x3 matrix"),
    ("scene_json_text_K", {"scene.json": '{"K": "eye"}'}, {}, "K must be a 3x3 matrix"),
    ("negative_depth_scale", {}, {"depth_scale": -5000.0}, "depth_scale must be a positive number"),
    ("nan_depth_scale", {}, {"depth_scale": float("nan")}, "depth_scale must be a positive"),
    ("negative_max_dt", {}, {"max_dt_s": -0.1}, "max_dt_s must be a time >= 0"),
    ("bad_groundtruth", {"groundtruth.txt": "1 0 0 0 0 0 0 0\n"}, {}, "groundtruth.txt: 1 quaternion"),
    ("bad_accelerometer", {"accelerometer.txt": "1 0 0\n"}, {}, "accelerometer.txt is not a TUM accelerometer file"),
    ("rgb_list_unsorted", {"rgb.txt": "0.2 rgb/0.png\n0.1 rgb/1.png\n"}, {},
     r"rgb.txt: line 2: timestamp 0.1 is not after"),
    ("depth_list_text", {"depth.txt": "zero depth/0.png\n"}, {}, r"depth.txt: line 1, column 1"),
    ("empty_rgb_list", {"rgb.txt": "# nothing\n"}, {}, "the image list holds no frames"),
    ("no_listed_image_exists", {"rgb.txt": "0.0 rgb/x.png\n0.1 rgb/y.png\n"}, {},
     "none of the 2 listed rgb images exist"),
]


@pytest.mark.parametrize("case, files, kwargs, message", FOLDER_CASES, ids=[c[0] for c in FOLDER_CASES])
def test_bad_tum_folders_name_the_file(tmp_path, case, files, kwargs, message):
    root = tum_folder(tmp_path / "seq", extra=files)
    with pytest.raises(InputError, match=message):
        load_tum_rgbd(root, **kwargs)


FRAME_CASES = [  # (id, file to overwrite, content, message)
    ("rgb_zero_bytes", "rgb/1.png", b"", "rgb/1.png: empty file"),
    ("rgb_truncated", "rgb/1.png", "TRUNCATED", "rgb/1.png: not a readable image.*truncated"),
    ("rgb_text", "rgb/1.png", "text", "rgb/1.png: not a readable image"),
    ("depth_eight_bit", "depth/1.png", np.full((8, 10), 5, np.uint8), "depth/1.png: expected 16-bit depth"),
    ("depth_wrong_size", "depth/1.png", np.full((4, 5), 5000, np.uint16),
     r"depth/1.png: expected depth of size \(8, 10\)"),
    ("depth_colour", "depth/1.png", np.full((8, 10, 3), 5000, np.uint16), "depth/1.png: expected a single-channel"),
    ("depth_missing", "depth/1.png", "DELETE", "depth/1.png: depth image not found"),
    ("rgb_deleted_after_loading", "rgb/1.png", "DELETE", "rgb/1.png: no such file"),
]


@pytest.mark.parametrize("case, name, content, message", FRAME_CASES, ids=[c[0] for c in FRAME_CASES])
def test_bad_frames_name_the_image_file(tmp_path, case, name, content, message):
    root = tum_folder(tmp_path / "seq")
    seq = load_tum_rgbd(root)
    path = root / name
    if isinstance(content, np.ndarray):
        cv2.imwrite(str(path), content)
    elif content == "DELETE":
        path.unlink()
    elif content == "TRUNCATED":
        path.write_bytes(path.read_bytes()[:40])
    else:
        write_case(root, content, name)
    assert seq.read_frame(0).depth.shape == (8, 10)  # the other frames still read
    with pytest.raises(InputError, match=message):
        seq.read_frame(1)


@pytest.mark.parametrize(
    "rgb_image, shape",
    [(np.full((8, 10), 7, np.uint8), (8, 10, 3)), (np.full((8, 10, 4), 7, np.uint8), (8, 10, 3)),
     (np.full((8, 10, 3), 7 * 257, np.uint16), (8, 10, 3))],
    ids=["grayscale", "rgba", "sixteen_bit"],
)
def test_awkward_rgb_images_are_converted_to_8_bit_rgb(tmp_path, rgb_image, shape):
    root = tum_folder(tmp_path / "seq")
    cv2.imwrite(str(root / "rgb" / "0.png"), rgb_image)
    frame = load_tum_rgbd(root).read_frame(0)
    assert frame.rgb.shape == shape and frame.rgb.dtype == np.uint8 and int(frame.rgb[0, 0, 0]) == 7


def test_missing_images_and_unpaired_depth_are_counted_not_lost(tmp_path):
    root = tum_folder(tmp_path / "seq", n=4, depth="0.0 depth/0.png\n0.1 depth/1.png\n")
    (root / "rgb" / "3.png").unlink()
    seq = load_tum_rgbd(root)
    assert len(seq) == 3 and seq.n_missing == 1 and seq.n_unpaired == 2  # rgb 2 and 3 have no depth
    assert seq.read_frame(2).depth is None


# ---------------------------------------------------------------- BROAD (HDF5)

h5py = pytest.importorskip("h5py")


def broad_file(path, n=20, **override):
    data = {"imu_gyr": np.zeros((n, 3)), "imu_acc": np.tile([0.0, 0.0, 9.81], (n, 1)),
            "opt_quat": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "movement": np.ones(n, bool), "sampling_rate": 286.0}
    data.update(override)
    with h5py.File(path, "w") as f:
        for key, value in data.items():
            if value is None:
                continue
            if key == "sampling_rate":
                f.attrs[key] = value
            else:
                f[key] = value
    return path


BROAD_CASES = [
    ("not_hdf5", lambda p: p.write_text("hello"), "Cannot read BROAD file"),
    ("empty_file", lambda p: p.write_bytes(b""), "Cannot read BROAD file"),
    ("missing_file", lambda p: None, "Cannot read BROAD file"),
    ("folder", lambda p: p.mkdir(), "Cannot read BROAD file"),
    ("no_gyro", lambda p: broad_file(p, imu_gyr=None), "lacks imu_gyr"),
    ("no_rate", lambda p: broad_file(p, sampling_rate=None), "lacks attribute sampling_rate"),
    ("no_quat_no_movement", lambda p: broad_file(p, opt_quat=None, movement=None), "lacks opt_quat, movement"),
    ("gyro_two_columns", lambda p: broad_file(p, imu_gyr=np.zeros((20, 2))), r"expected imu_gyr/imu_acc \(N, 3\)"),
    ("accel_shorter", lambda p: broad_file(p, imu_acc=np.zeros((10, 3))), r"\(10, 3\)"),
    ("quat_three", lambda p: broad_file(p, opt_quat=np.zeros((20, 3))), r"opt_quat \(N, 4\)"),
    ("zero_rate", lambda p: broad_file(p, sampling_rate=0.0), "sampling_rate must be positive, got 0"),
    ("nan_rate", lambda p: broad_file(p, sampling_rate=np.nan), "sampling_rate must be positive, got nan"),
    ("negative_rate", lambda p: broad_file(p, sampling_rate=-100.0), "sampling_rate must be positive"),
    ("text_rate", lambda p: broad_file(p, sampling_rate="fast"), "sampling_rate must be a number"),
    ("nan_gyro", lambda p: broad_file(p, imu_gyr=np.where(np.arange(20)[:, None] == 4, np.nan, np.zeros((20, 3)))),
     r"imu_gyr holds NaN or infinite values in 1 row\(s\) \(first: sample 4\)"),
    ("inf_acc", lambda p: broad_file(p, imu_acc=np.full((20, 3), np.inf)),
     r"imu_acc holds NaN or infinite values in 20 row"),
    ("text_gyro", lambda p: broad_file(p, imu_gyr=np.full((20, 3), "x".encode())), "imu_gyr is not numeric"),
]


@pytest.mark.parametrize("case, make, message", BROAD_CASES, ids=[c[0] for c in BROAD_CASES])
def test_bad_broad_files_name_the_file_and_dataset(tmp_path, case, make, message):
    path = tmp_path / "trial.hdf5"
    make(path)
    with pytest.raises(InputError) as info:
        read_broad(path)
    assert str(path) in str(info.value) and re.search(message, str(info.value)), str(info.value)


def test_broad_missing_optical_reference_is_nan_not_an_error(tmp_path):
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (20, 1))
    quat[5:8] = np.nan
    trial = read_broad(broad_file(tmp_path / "t.hdf5", opt_quat=quat))
    R = trial.R_ref_imu
    assert np.isnan(R[5:8]).all() and np.isfinite(np.delete(R, [5, 6, 7], axis=0)).all()
