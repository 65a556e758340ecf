"""The stream's Manhattan labelling (`backends/labelling_track.py`, used by the `single` backend): a run of
wrong, wide frames does not walk the labelling to a neighbouring one; confident frames set it."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.backends.labelling_track import LabellingTrack, LabellingTrackConfig
from uareme_fusion.backends.single import SingleFrame
from uareme_fusion.rotations import angle_between, exp_so3, nearest_symmetric
from uareme_fusion.types import VisualRotation

FPS = 30.0
RATE_DEG_S = 60.0
"""The true camera turns at 60 deg/s about a fixed axis (TUM fr1 rpy: 60 deg/s mean, 175 at most)."""
GOOD_STD_DEG, WRONG_STD_DEG = 2.0, 25.0


def _visual(R_cm, std_deg: float, t_s: float) -> VisualRotation:
    return VisualRotation(np.asarray(R_cm, float), np.radians(std_deg) ** 2 * np.eye(3), 0.1, 5, 1000, t_s=t_s)


def _stream(seed: int = 0, wrong=range(30, 42), frames: int = 90):
    """(t_s, true R_cm, visuals): good frames with 2 deg noise, and over `wrong` a wrong minimum that walks
    away from the truth about the Manhattan z axis by 4.5 deg per frame (to 54 deg), each frame 25 deg
    wide; every visual is given in a random one of the 24 labellings, as a solver without a prior would."""
    rng = np.random.default_rng(seed)
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    R0 = Rotation.from_euler("xyz", [10, 20, 5], degrees=True).as_matrix()
    from uareme_fusion.rotations import manhattan_symmetries

    G = manhattan_symmetries()
    t, truth, visuals = [], [], []
    for k in range(frames):
        t_s = k / FPS
        R_true = exp_so3(np.radians(RATE_DEG_S) * t_s * axis) @ R0
        if k in wrong:
            offset = np.radians(4.5 * (k - wrong.start + 1))
            R, std = R_true @ exp_so3([0.0, 0.0, offset]), WRONG_STD_DEG
        else:
            R, std = R_true @ exp_so3(np.radians(GOOD_STD_DEG) * rng.standard_normal(3)), GOOD_STD_DEG
        t.append(t_s)
        truth.append(R_true)
        visuals.append(_visual(R @ G[rng.integers(24)], std, t_s))
    return np.array(t), np.array(truth), visuals


def _mislabelled(R_cm: np.ndarray, truth: np.ndarray, frames) -> int:
    """Frames among `frames` whose labelled rotation is more than 30 deg from the truth (a wrong labelling:
    the good frames are 2 deg off)."""
    return int(np.sum(np.degrees(angle_between(R_cm[frames], truth[frames])) > 30.0))


def _in_truths_labelling(labelled: list, visuals: list, truth: np.ndarray) -> np.ndarray:
    """The labelled rotations turned into the truth's labelling by the one relabelling that takes the
    first frame (whose labelling a stream keeps) to it."""
    P0 = nearest_symmetric(visuals[0].R_cm, truth[0])[1]
    return np.array(labelled) @ P0


def test_a_run_of_wrong_wide_frames_keeps_the_labelling():
    t, truth, visuals = _stream()
    track = LabellingTrack()
    labelled = _in_truths_labelling([track.label(t_s, v).R_cm for t_s, v in zip(t, visuals)], visuals, truth)
    assert _mislabelled(labelled, truth, list(range(0, 30)) + list(range(42, 90))) == 0


def test_labelling_nearest_the_previous_frame_flips_on_the_same_stream():
    """The oracle the track replaces: each frame nearest the previous one walks with the wrong minimum."""
    t, truth, visuals = _stream()
    prev, labelled = None, []
    for v in visuals:
        v = v if prev is None else v.symmetric_to(prev)
        prev = v.R_cm
        labelled.append(v.R_cm)
    assert _mislabelled(_in_truths_labelling(labelled, visuals, truth), truth, range(42, 90)) == 48


def test_a_confident_frame_beyond_the_gate_is_labelled_but_does_not_move_the_track():
    track = LabellingTrack()
    R = Rotation.from_euler("xyz", [5, -10, 30], degrees=True).as_matrix()
    track.label(0.0, _visual(R, 1.0, 0.0))
    off = R @ exp_so3(np.radians([0.0, 25.0, 0.0]))
    out = track.label(1 / FPS, _visual(off, 1.0, 1 / FPS))
    assert track.rejected == 1
    assert np.degrees(angle_between(out.R_cm, off)) == pytest.approx(0.0, abs=1e-9)  # the frame's own rotation
    assert np.degrees(angle_between(track.R_cm, R)) == pytest.approx(0.0, abs=1e-9)


def test_a_frame_inside_the_gate_moves_the_track_by_the_kalman_gain():
    track = LabellingTrack(LabellingTrackConfig(rate_std_rad_s=0.0))
    R = np.eye(3)
    track.label(0.0, _visual(R, 3.0, 0.0))
    step = np.radians([0.0, 0.0, 4.0])
    track.label(0.1, _visual(exp_so3(step), 3.0, 0.1))  # equal covariances: half way, variance halved
    assert np.degrees(angle_between(track.R_cm, exp_so3(step / 2))) == pytest.approx(0.0, abs=1e-6)
    assert track.cov == pytest.approx(np.radians(3.0) ** 2 / 2 * np.eye(3))


def test_the_track_widens_with_time_by_the_rate_and_at_most_over_max_gap():
    config = LabellingTrackConfig(rate_std_rad_s=np.radians(100.0), max_gap_s=1.0)
    track = LabellingTrack(config)
    track.label(0.0, _visual(np.eye(3), 1.0, 0.0))
    P0 = np.radians(1.0) ** 2
    assert track.predicted(0.1)[1] == pytest.approx((P0 + np.radians(10.0) ** 2) * np.eye(3))
    assert track.predicted(5.0)[1] == pytest.approx(track.predicted(1.0)[1])
    assert LabellingTrack().predicted(0.0) is None


def test_a_frame_with_a_covariance_that_is_not_finite_is_labelled_and_not_fused():
    track = LabellingTrack()
    track.label(0.0, _visual(np.eye(3), 1.0, 0.0))
    bad = VisualRotation(exp_so3([0.0, 0.0, np.radians(88.0)]), np.full((3, 3), np.nan), 0.1, 5, 1000)
    out = track.label(0.03, bad)
    assert np.degrees(angle_between(out.R_cm, np.eye(3))) == pytest.approx(2.0, abs=1e-6)  # relabelled near
    assert np.degrees(angle_between(track.R_cm, np.eye(3))) == pytest.approx(0.0, abs=1e-9)


def test_single_backend_reports_each_frames_own_rotation_in_the_tracks_labelling():
    t, truth, visuals = _stream(seed=3)
    backend = SingleFrame()
    for t_s, v in zip(t, visuals):
        predicted = backend.predicted_R_cm(t_s)
        est = backend.process_frame(t_s, v)
        R_cm = est.R_wc.T
        assert np.allclose(R_cm, nearest_symmetric(v.R_cm, R_cm)[0])  # one of the frame's own labellings
        if predicted is not None:
            assert np.allclose(R_cm, nearest_symmetric(v.R_cm, predicted)[0])  # the one nearest the track
    assert backend.track.rejected == 0


def test_confident_frames_that_keep_disagreeing_restart_the_track():
    """Image rotations that drifted (a biased focal length) must not lock the frames' evidence out."""
    config = LabellingTrackConfig(rate_std_rad_s=0.0, restart_after_rejected=5)  # a track that does not widen
    track = LabellingTrack(config)
    R = np.eye(3)
    track.label(0.0, _visual(R, 1.0, 0.0))
    off = exp_so3(np.radians([0.0, 20.0, 0.0]))
    for k in range(1, 5):
        track.label(k / FPS, _visual(off, 1.0, k / FPS))
    assert track.rejected == 4 and track.restarts == 0
    assert np.degrees(angle_between(track.R_cm, R)) == pytest.approx(0.0, abs=1e-9)
    track.label(5 / FPS, _visual(off, 1.0, 5 / FPS))  # the fifth in a row: the evidence wins
    assert track.restarts == 1 and np.degrees(angle_between(track.R_cm, off)) == pytest.approx(0.0, abs=1e-9)
    out = track.label(6 / FPS, _visual(off, 1.0, 6 / FPS))
    assert track.rejected == 5 and np.degrees(angle_between(out.R_cm, off)) == pytest.approx(0.0, abs=1e-9)
