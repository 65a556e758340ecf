"""The visual-only EKF predicted by the image rotation between frames (`image_rotation_motion.py`): the
kernel's prediction against its model and the oracle's, noiseless convergence, a fast handheld sweep
followed better than by the constant-rate model, a wrong image rotation flagged and re-initialised
from, frames without a visual rotation in between, and the real TUM training frames (slow, skipped
without them). Hand-made streams, navlie style."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jacobians import fd_jacobian

from uareme_fusion.backends.mekf import Mekf, MekfConfig, kernel_image_rotation
from uareme_fusion.backends.mekf.image_rotation_motion import ImageRotationMotion
from uareme_fusion.backends.mekf.motion import ConstantRateMotion
from uareme_fusion.backends.mekf.state import N_STATE, RATE, TH
from uareme_fusion.backends.mekf.state_buffer import field_views, new_state_buffer, python_state
from uareme_fusion.backends.single import SingleFrame
from uareme_fusion.rotations import exp_so3, log_so3, nees
from uareme_fusion.types import Status

from mekf_oracle import OracleMekf  # tests/backends/mekf_oracle: pytest puts tests/backends on sys.path
from mekf_oracle.propagation import image_rotation_model
from test_visual_only_labelling import are_deg, handheld_truth
from test_mekf import visual_measurement


def plain(f):
    return getattr(f, "py_func", f)


def image_rotation_step(R_wc, P, R_cp, var, dt_s, q_rate):
    """`kernel_image_rotation.image_rotation_predict` from a state buffer at t = 0: `(R_wc, omega, P)` at `dt_s`."""
    x = new_state_buffer()
    views = field_views(x)
    views["R_wc"][...], views["P"][...] = R_wc, P
    x["t_state_s"] = 0.0
    plain(kernel_image_rotation.image_rotation_predict)(python_state(x), dt_s, R_cp, var, q_rate)
    assert x["t_state_s"][0] == dt_s
    return views["R_wc"].copy(), views["omega_c"].copy(), views["P"].copy()


def test_image_rotation_prediction_against_its_model():
    """`R_wc <- R_wc R_cp^T`; the attitude block of `F` (finite differences of a perturbed start) is
    `R_cp`, the image rotation's variance is added, and the rate is the step's, `Log(R_cp^T) / dt`, with
    the covariance the oracle's model gives."""
    rng = np.random.default_rng(3)
    R0, R_cp = exp_so3(rng.normal(size=3)), exp_so3(np.radians([2.0, -1.0, 0.5]))
    A = rng.normal(size=(N_STATE, N_STATE))
    P = 1e-3 * A @ A.T
    R_N, omega, P_N = image_rotation_step(R0, P, R_cp, 1e-5, 1 / 30, 9.0)
    np.testing.assert_allclose(R_N, R0 @ R_cp.T, atol=1e-12)
    np.testing.assert_allclose(omega, log_so3(R_cp.T) * 30, atol=1e-9)
    fd = fd_jacobian(lambda d: log_so3(R_N.T @ R0 @ exp_so3(d) @ R_cp.T), 3)
    np.testing.assert_allclose(fd, R_cp, atol=1e-8)
    omega_ref, P_ref = image_rotation_model(R_cp, 1e-5, 1 / 30, 9.0, P)
    np.testing.assert_allclose(P_N, P_ref, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(P_N, P_N.T)
    np.testing.assert_allclose(P_N[TH, TH], R_cp @ P[TH, TH] @ R_cp.T + 1e-5 * np.eye(3), atol=1e-15)
    assert np.all(np.linalg.eigvalsh(P_N[RATE, RATE]) > 0)


def image_stream(t, R_wc, visual_std_rad, cp_std_rad, seed, cp_error=None, missing=()):
    """Frames of `R_wc` (noise `visual_std_rad`, random labelling) carrying the image rotation since the
    previous frame with a visual rotation (noise `cp_std_rad`, stated as such); `cp_error` (frame ->
    rotation) makes that frame's `R_cp` wrong by it; frames in `missing` give no visual rotation."""
    rng = np.random.default_rng(seed)
    cov = visual_std_rad**2 * np.eye(3)
    frames, previous = [], None
    for k, R in enumerate(R_wc):
        if k in missing:
            frames.append(None)
            continue
        vis = visual_measurement(R.T, cov, rng)
        if previous is not None:
            R_cp = exp_so3(rng.normal(0.0, cp_std_rad, 3)) @ R.T @ R_wc[previous]
            if cp_error and k in cp_error:
                R_cp = cp_error[k] @ R_cp
            vis = dataclasses.replace(vis, R_cp=R_cp, R_cp_std_rad=max(cp_std_rad, 1e-6))
        frames.append(vis)
        previous = k
    return frames


def run(backend, t, frames, predict_first=False):
    ests = []
    for t_s, vis in zip(t, frames):
        if predict_first:
            backend.predicted_R_cm(float(t_s))  # as the pipeline asks before solving the frame
        ests.append(backend.process_frame(float(t_s), vis))
    return ests


def visual_only(**keys):
    return Mekf(MekfConfig(mode="visual_only", **keys))


def test_the_visual_only_filter_is_predicted_by_the_image_rotation_and_converges_without_noise():
    t, R_wc = handheld_truth(3.0)
    filt = visual_only()
    assert isinstance(filt.motion, ImageRotationMotion)
    assert isinstance(visual_only(visual_only_image_rotation=False).motion, ConstantRateMotion)
    ests = run(filt, t, image_stream(t, R_wc, 1e-5, 0.0, 0))
    assert are_deg(ests, R_wc).max() < 1e-3
    assert filt.counters["visual_ignored"] == filt.counters["reinitialised"] == 0


def test_a_fast_handheld_sweep_is_followed_better_than_by_the_constant_rate_model_and_consistently():
    """100 deg/s sweeps, frames 3 deg off (independent), image rotations 0.3 deg: the image rotation
    carries the filter between frames; the constant-rate model has to lean on each frame. Seeded."""
    t, R_wc = handheld_truth(6.0)
    frames = image_stream(t, R_wc, np.radians(3.0), np.radians(0.3), 5)
    image = visual_only(visual_noise_share_frames=0)
    rate = visual_only(visual_noise_share_frames=0, visual_only_image_rotation=False)
    are_image, are_rate = are_deg(run(image, t, frames), R_wc), are_deg(run(rate, t, frames), R_wc)
    are_single = are_deg(run(SingleFrame(), t, frames), R_wc)
    assert are_image.mean() < 0.6 * are_rate.mean() and are_image.mean() < 0.5 * are_single.mean()
    ests = run(visual_only(visual_noise_share_frames=0), t, frames)
    n = nees(np.array([e.R_wc for e in ests]), R_wc, np.array([e.cov for e in ests]))[30:]
    assert 0.3 < n.mean() < 3.0


def test_a_wrong_image_rotation_is_flagged_and_the_filter_reinitialises_after_the_disagreement_time():
    """One image rotation 30 deg wrong: the prediction is then off by it and every frame disagrees
    (flagged VISUAL_IGNORED) until the filter re-initialises from the frames (here after
    `reinit_after_rejections` frames beyond the gate, before `reinit_after_disagreement_s`) and follows
    them again."""
    t, R_wc = handheld_truth(4.0)
    frames = image_stream(t, R_wc, np.radians(1.0), np.radians(0.2), 7, cp_error={45: exp_so3(np.radians([0, 30, 0]))})
    filt = visual_only()
    ests = run(filt, t, frames)
    ignored = [k for k, e in enumerate(ests) if e.status & Status.VISUAL_IGNORED]
    reinit = [k for k, e in enumerate(ests) if e.status & Status.REINITIALISED]
    assert ignored and ignored[0] == 45
    assert len(reinit) == 1 and reinit[0] == 45 + filt.config.reinit_after_rejections - 1
    assert np.all([k in ignored for k in range(45, reinit[0])])
    after = slice(reinit[0] + 5, None)
    assert are_deg(ests[after], R_wc[after]).mean() < 1.0 and filt.counters["reinitialised"] == 1


def test_frames_without_a_visual_rotation_are_spanned_by_the_next_image_rotation():
    """A frame without a visual rotation is predicted by the rate; the next frame's image rotation spans
    both, from the state before it: the same estimate as a stream without that frame."""
    t, R_wc = handheld_truth(2.0)
    full = image_stream(t, R_wc, np.radians(1.0), np.radians(0.2), 9, missing=(20, 21))
    without = [f for k, f in enumerate(full) if k not in (20, 21)]
    t_without = np.delete(t, [20, 21])
    a, b = run(visual_only(), t, full), run(visual_only(), t_without, without)
    np.testing.assert_allclose(a[22].R_wc, b[20].R_wc, atol=1e-12)
    np.testing.assert_allclose(a[-1].R_wc, b[-1].R_wc, atol=1e-12)


def test_a_prediction_asked_before_the_frame_leaves_the_filter_where_it_is():
    """`predicted_R_cm` (the pipeline's, before solving a frame) moves nothing, and a propagation asked
    before the frame (`evaluation.scenarios`) is redone from the frame's image rotation."""
    t, R_wc = handheld_truth(2.0)
    frames = image_stream(t, R_wc, np.radians(1.0), np.radians(0.2), 11)
    a, b = run(visual_only(), t, frames), run(visual_only(), t, frames, predict_first=True)
    np.testing.assert_allclose(np.array([e.R_wc for e in a]), np.array([e.R_wc for e in b]), atol=1e-12)
    filt, c = visual_only(), []
    for t_s, vis in zip(t, frames):
        filt.propagate_to(float(t_s))
        c.append(filt.process_frame(float(t_s), vis))
    np.testing.assert_allclose(np.array([e.R_wc for e in a]), np.array([e.R_wc for e in c]), atol=1e-12)
    np.testing.assert_allclose(np.array([e.cov for e in a]), np.array([e.cov for e in c]), atol=1e-15)


@pytest.mark.parametrize("bias_std_rad", [0.0, 0.05])
def test_the_kernels_match_the_oracle_on_an_image_rotation_stream(bias_std_rad):
    t, R_wc = handheld_truth(3.0)
    frames = image_stream(t, R_wc, np.radians(2.0), np.radians(0.3), 13, missing=(30,),
                          cp_error={60: exp_so3(np.radians([0, 25, 0]))})
    cfg = MekfConfig(mode="visual_only", image_rotation_visual_bias_std_rad=bias_std_rad)
    a, b = run(Mekf(cfg), t, frames), run(OracleMekf(cfg), t, frames)
    np.testing.assert_allclose(np.array([e.R_wc for e in a]), np.array([e.R_wc for e in b]), atol=1e-9)
    np.testing.assert_allclose(np.array([e.cov for e in a]), np.array([e.cov for e in b]), rtol=1e-6, atol=1e-12)
    assert [int(e.status) for e in a] == [int(e.status) for e in b]


def test_a_source_without_intrinsics_is_propagated_by_its_image_rotation_too():
    """Its K is estimated from the scene and the image rotation's std widened for it at the source
    (`FrameMotionConfig.scene_K_std_scale`), so the run's EKF is the same as with a K given; a run config
    may still ask for the constant-rate model."""
    from uareme_fusion.drivers.base import SourceInfo
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.stages import backend_for_run

    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    for info in (SourceInfo(name="a", K=K, has_frames=True), SourceInfo(name="b", K=None, has_frames=True)):
        backend = backend_for_run(RunConfig(backend="mekf"), info)
        backend.resolve_mode(backend.mode.VISUAL_ONLY)
        assert isinstance(backend.motion, ImageRotationMotion)
        asked = backend_for_run(RunConfig(backend="mekf", mekf={"visual_only_image_rotation": False}), info)
        asked.resolve_mode(asked.mode.VISUAL_ONLY)
        assert not isinstance(asked.motion, ImageRotationMotion)


@pytest.mark.slow
def test_tum_training_frames_rgb_image_rotation_beats_the_constant_rate_model(tmp_path):
    """Real TUM fr1 rpy training frames (handheld, learned normals and lines, RGB only), the first 150:
    the image rotation against the constant-rate model and `single` on the same rotations."""
    from uareme_fusion.benchmarks import realdata
    from uareme_fusion.evaluation.paired_difference import paired_difference
    from uareme_fusion.formats.fetched import tum_rpy_root, tum_rpy_split

    root = tum_rpy_root()
    if root is None:
        pytest.skip("the fetched TUM freiburg1_rpy folder is not there (formats.fetched.tum_rpy_root)")
    seq = realdata.RealSequence("tum_train", "TUM fr1 rpy train", str(tum_rpy_split(root, "train", tmp_path)))
    visual, info, _ = realdata.cue_set_sequence(seq, "learned", "normals,lines", 150, lambda *a: None)
    assert sum(v is not None and v.has_image_rotation() for v in visual.visuals) > 140
    t, truth = visual.t_frame_s, visual.R_wc_true
    single = are_deg(run(SingleFrame(), t, visual.visuals), truth)
    image = are_deg(run(visual_only(), t, visual.visuals), truth)
    rate = are_deg(run(visual_only(visual_only_image_rotation=False), t, visual.visuals), truth)
    figures = (image.mean(), rate.mean(), single.mean())
    assert image.mean() < rate.mean() and paired_difference(image, single)["high"] < 0.0, figures
