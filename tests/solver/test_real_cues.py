"""Cues that never make each other worse on a real camera (issue 29 item 2)."""

import numpy as np
import pytest


@pytest.mark.slow
def test_segments_near_chance_do_not_make_the_joint_worse_than_the_normals_on_euroc_micro():
    """Real EuRoC cam0 (static drone, a cluttered room): the segments fit the frame barely above chance
    (lines alone tilt 8.6 deg off) but their information before the discount is ~2600 times the network
    normals'; they used to take 97 % of the joint's information: joint ARE 1.16 deg against 0.65 alone."""
    from helpers import shared_data_or_skip

    from uareme_fusion.benchmarks.realdata import backend_errors, cue_set_sequence, sequences
    from uareme_fusion.benchmarks.realdata_rows import NO_WORSE_TOLERANCE_DEG
    from uareme_fusion.evaluation.paired_difference import paired_difference

    found, _ = sequences(shared_data_or_skip(), None, ("euroc",))
    if not found:
        pytest.skip("euroc_v1_01_micro not found")
    are = {}
    for cues in ("normals,lines", "normals"):
        visual, info, _ = cue_set_sequence(found[0], "learned", cues, None, None)
        are[cues] = backend_errors(visual, info, "learned")["single"]["are_deg"]
        if cues == "normals,lines":
            shares = [v.cues["lines"]["share"] for v in visual.visuals if v is not None and "lines" in v.cues]
            assert np.median(shares) < 0.1  # 0.97 before
    d = paired_difference(are["normals,lines"], are["normals"])
    assert d["low"] <= NO_WORSE_TOLERANCE_DEG  # +0.14 before; the same frames to 1e-13 deg now (the bench's float noise)
    assert np.nanmean(are["normals,lines"]) <= np.nanmean(are["normals"]) + 0.1  # 0.65 vs 0.65 (1.16 before)
