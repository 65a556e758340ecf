"""Real data (skipped without it): depth-normal covariances on a real Kinect mean what they say (issue 29),
and real frames are never judged as frames without evidence."""

import numpy as np
import pytest

from uareme_fusion.drivers import open_source
from uareme_fusion.formats.fetched import tum_rpy_root, tum_rpy_split
from uareme_fusion.normals.depth import DepthNormals
from uareme_fusion.rotations import align_constant, nees
from uareme_fusion.solver import solve_manhattan
from uareme_fusion.solver.evidence import NO_EVIDENCE_TEXTURED_FRACTION, no_evidence_reason, textured_fraction
from uareme_fusion.types import ImuBatch, visual_R_wc_covariance

FRAMES = 60


@pytest.fixture(scope="module")
def tum_eval_frames(tmp_path_factory):
    root = tum_rpy_root()
    if root is None:
        pytest.skip("the fetched TUM freiburg1_rpy folder is not there (formats.fetched.tum_rpy_root)")
    folder = tum_rpy_split(root, "eval", tmp_path_factory.mktemp("tum"))
    with open_source(str(folder)) as source:
        truth = source.ground_truth()
        frames = [e for e in source.events() if not isinstance(e, ImuBatch) and e.depth is not None][:FRAMES]
    return frames, truth


def test_depth_normal_nees_on_a_real_kinect_is_inside_1_to_6(tum_eval_frames):
    frames, truth = tum_eval_frames
    depth, R_prev, R_wc, cov = DepthNormals(), None, [], []
    for frame in frames:
        visual = solve_manhattan(depth.estimate_frame(frame), R_init=R_prev)
        visual = visual if R_prev is None else visual.symmetric_to(R_prev)
        R_prev = visual.R_cm
        R_wc.append(visual.R_cm.T)
        cov.append(visual_R_wc_covariance(visual))
    R_true, ok = truth.at(np.array([f.t_s for f in frames]))
    R_wc = np.array(R_wc)[ok]
    errors = nees(align_constant(R_wc, R_true[ok]) @ R_wc, R_true[ok], np.array(cov)[ok])
    assert 1.0 <= errors.mean() <= 6.0  # 131 on the whole evaluation split before the region cap


def test_real_frames_hold_image_evidence(tum_eval_frames):
    frames, _ = tum_eval_frames
    fractions = [textured_fraction(f.rgb) for f in frames[::10]]
    assert min(fractions) > 5 * NO_EVIDENCE_TEXTURED_FRACTION
    # at their own pixels too (blur): 0.119 at least over the 207 evaluation frames
    assert min(textured_fraction(f.rgb, 640) for f in frames) > 3 * NO_EVIDENCE_TEXTURED_FRACTION
    assert all(no_evidence_reason(f.rgb) == "" for f in frames)
