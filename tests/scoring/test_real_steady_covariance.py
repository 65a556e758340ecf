"""Real data (skipped without it): the principal point's floor is a steady error on the ICSL corridor."""

import numpy as np
import pytest


@pytest.mark.slow
def test_icsl_corridor_segments_are_scored_against_their_per_frame_error():
    """ICSL corridor (80 frames, no intrinsics: K pooled from the scene, its centre taken at the image
    centre): the segments' rotations after the constant alignment err by 0.19 deg per axis while the
    principal point's floor alone is 1.34 deg. Scored against the whole covariance, NEES 0.06; the floor is
    the frames' steady part, which the alignment removes from a camera that turns 2 deg in all."""
    from helpers import shared_data_or_skip

    from uareme_fusion.benchmarks.realdata import backend_errors, cue_set_sequence, sequences

    found, _ = sequences(shared_data_or_skip(), None, ("icsl",))
    if not found:
        pytest.skip("icsl_corridor not found")
    visual, info, _ = cue_set_sequence(found[0], "learned", "lines", None, None)
    frames = [v for v in visual.visuals if v is not None and "lines" in v.cues]
    steady_std_deg = np.degrees(np.sqrt([np.trace(v.cov_steady) / 3 for v in frames]))
    frame_std_deg = np.degrees(np.sqrt([np.trace(v.cov_frame()) / 3 for v in frames]))
    assert np.median(steady_std_deg) == pytest.approx(1.34, abs=0.05)  # 0.02 * 640 / f, f 547 px pooled
    assert np.median(frame_std_deg) < 0.3
    nees = np.nanmean(backend_errors(visual, info, "learned")["single"]["nees"])
    assert 1.0 <= nees <= 6.0  # 0.06 against the whole covariance


@pytest.mark.slow
def test_euroc_still_drone_normals_are_scored_against_what_the_stream_shows_varying():
    """EuRoC V1_01 micro (95 frames, the drone standing still, K given: no calibration steady part): the
    learned normals' rotations are 5 deg off in tilt with a std of 9.9 deg per axis, one error the frames
    share, and after the constant alignment err by 0.65 deg. Scored against the whole covariance, single's
    NEES 0.01; against what the stream shows varying (`backends/stream_steady.py`) 1.12 (round-1 network). The
    round-4 network, mirror-averaged (docs/normals_training.md): ARE 0.81, NEES 1.17 (0.86 / 0.89 without the
    mirror average); here the scoring's own job, 0.01 -> about 1, is asserted."""
    from helpers import shared_data_or_skip

    from uareme_fusion.benchmarks.realdata import backend_errors, cue_set_sequence, sequences

    found, _ = sequences(shared_data_or_skip(), None, ("euroc",))
    if not found:
        pytest.skip("euroc_v1_01_micro not found")
    visual, info, _ = cue_set_sequence(found[0], "learned", "normals", None, None)
    single = backend_errors(visual, info, "learned")["single"]
    assert np.nanmean(single["are_deg"]) < 1.0  # 0.81 (round 1: 0.65)
    assert 0.8 <= np.nanmean(single["nees"]) <= 6.0  # 1.17 (round 1: 1.12)
