"""The ground truth's clock offset: estimated from rotations (`evaluation.time_offset`) on synthetic
stamps, applied to TUM RGB-D folders only as their dataset default (`drivers.tum`), and replaced by
`--gt-time-offset-s` (`drivers.ground_truth_file.with_ground_truth_time_offset`)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.drivers import open_source
from uareme_fusion.drivers.base import GroundTruth
from uareme_fusion.drivers.ground_truth_file import with_ground_truth_time_offset
from uareme_fusion.drivers.tum import TumSource
from uareme_fusion.errors import InputError
from uareme_fusion.evaluation.time_offset import estimate_time_offset, relabel_to_reference
from uareme_fusion.formats.tum import TUM_RGBD_GT_TIME_OFFSET_S
from uareme_fusion.rotations import angle_between, manhattan_symmetries


def _turning(t_s: np.ndarray) -> np.ndarray:
    """A handheld-like turn: roll, pitch and yaw swinging at 0.5-1.5 rad/s."""
    angles = np.column_stack([0.4 * np.sin(2.1 * t_s), 0.3 * np.sin(3.3 * t_s + 1.0), 0.5 * np.sin(1.7 * t_s + 2.0)])
    return Rotation.from_euler("xyz", angles).as_matrix()


def _mocap(offset_s: float = 0.0) -> GroundTruth:
    t = np.arange(0.0, 12.0, 0.01)  # 100 Hz, like the TUM motion capture
    return GroundTruth(t - offset_s, _turning(t))  # stamped offset_s early: + offset_s puts it back


@pytest.mark.parametrize("offset_s", [0.0, 0.025, -0.04])
def test_estimate_recovers_the_offset_through_noise_relabelling_and_outliers(offset_s):
    rng = np.random.default_rng(3)
    t = np.arange(1.0, 11.0, 1 / 30)
    R_est = _turning(t) @ Rotation.from_rotvec(rng.normal(0, np.radians(2.0), (len(t), 3))).as_matrix()
    R_est = Rotation.from_euler("z", 40, degrees=True).as_matrix() @ R_est  # another world: aligned
    G = manhattan_symmetries()
    switched = rng.random(len(t)) < 0.3  # a stream that changed its axis labels on 30 % of the frames
    R_est[switched] = G[rng.integers(1, 24, switched.sum())] @ R_est[switched]
    wild = rng.choice(len(t), 10, replace=False)
    R_est[wild] = Rotation.random(10, random_state=1).as_matrix()
    est = estimate_time_offset(t, R_est, _mocap(offset_s))
    assert est.offset_s == pytest.approx(offset_s, abs=0.003)
    assert est.frames >= len(t) - 10
    assert est.low_s <= est.offset_s <= est.high_s and est.high_s - est.low_s < 0.02
    if offset_s:
        assert est.are_deg_at_offset < est.are_deg_at_zero - 0.2


def test_relabelling_undoes_axis_switches():
    t = np.arange(0.0, 3.0, 0.1)
    R_true = _turning(t)
    A = Rotation.from_euler("xz", [20, 70], degrees=True).as_matrix()
    labels = np.random.default_rng(0).integers(0, 24, len(t))
    R_est = manhattan_symmetries()[labels] @ A @ R_true
    R_rel = relabel_to_reference(R_est, R_true)
    R_rel_0 = R_rel[0] @ R_true[0].T  # one world for every frame after relabelling
    assert np.degrees(angle_between(R_rel @ np.swapaxes(R_true, 1, 2), R_rel_0[None])).max() < 1e-6


def test_estimate_refuses_too_few_frames():
    with pytest.raises(InputError):
        estimate_time_offset(np.array([0.0, 1.0]), np.stack([np.eye(3)] * 2), _mocap())


def _folder(root, name: str, scene_json: bool = False):
    """A tiny TUM RGB-D layout under `root/name`: 3 black 640x480 frames 1/30 s apart, ground truth at 100 Hz."""
    folder = root / name
    (folder / "rgb").mkdir(parents=True)
    t = 100.0 + np.arange(3) / 30
    for ti in t:
        cv2.imwrite(str(folder / "rgb" / f"{ti:.6f}.png"), np.zeros((480, 640, 3), np.uint8))
    (folder / "rgb.txt").write_text("".join(f"{ti:.6f} rgb/{ti:.6f}.png\n" for ti in t))
    t_gt = np.arange(99.5, 101.0, 0.01)
    q = Rotation.from_matrix(_turning(t_gt)).as_quat()
    (folder / "groundtruth.txt").write_text("".join(f"{ti:.4f} 0 0 0 {q[i, 0]} {q[i, 1]} {q[i, 2]} {q[i, 3]}\n"
                                                    for i, ti in enumerate(t_gt)))
    if scene_json:
        (folder / "scene.json").write_text(json.dumps({"fps": 30}))
    return folder, t_gt


def test_tum_rgbd_folders_get_the_default_offset_with_a_note_and_others_none(tmp_path):
    tum, t_gt = _folder(tmp_path, "rgbd_dataset_freiburg1_test")
    with TumSource(tum) as source:
        assert source.info.gt_time_offset_s == TUM_RGBD_GT_TIME_OFFSET_S
        np.testing.assert_allclose(source.ground_truth().t_s, t_gt + TUM_RGBD_GT_TIME_OFFSET_S)
        assert any("TUM RGB-D default" in note and f"{TUM_RGBD_GT_TIME_OFFSET_S * 1000:+.0f} ms" in note
                   for note in source.notes)
    for name, scene in (("my_desk_sequence", False), ("rgbd_dataset_freiburg1_sim", True)):
        other, t_gt = _folder(tmp_path, name, scene_json=scene)
        with TumSource(other) as source:
            assert source.info.gt_time_offset_s == 0.0
            np.testing.assert_allclose(source.ground_truth().t_s, t_gt)
            assert not any("ground" in note and "ms" in note for note in source.notes)


def test_gt_time_offset_option_replaces_the_default(tmp_path):
    tum, t_gt = _folder(tmp_path, "rgbd_dataset_freiburg1_test")
    with open_source(str(tum)) as source:
        with_ground_truth_time_offset(source, 0.005)
        np.testing.assert_allclose(source.ground_truth().t_s, t_gt + 0.005)
        assert source.info.gt_time_offset_s == 0.005
        assert any("--gt-time-offset-s" in note and "+5 ms" in note for note in source.notes)
    other, t_gt = _folder(tmp_path, "my_desk_sequence")
    with open_source(str(other)) as source:
        with_ground_truth_time_offset(source, -0.01)
        np.testing.assert_allclose(source.ground_truth().t_s, t_gt - 0.01)
    with pytest.raises(InputError):
        with_ground_truth_time_offset(TumSource(other), float("nan"))
