"""Summary counts: frames with ARE above 10 deg, and real frame-to-frame jumps (issue 16)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.scoring.metrics import attitude_errors, error_summary, step_errors_deg


def test_one_jump_is_one_frame_jump_however_many_frames_it_leaves_off():
    t = np.linspace(0, 2, 40)
    R_true = Rotation.from_euler("zyx", np.column_stack([30 * t, 5 * np.sin(t), 3 * t]), degrees=True).as_matrix()
    R_est = R_true.copy()
    R_est[25:] = R_est[25:] @ Rotation.from_euler("x", 40, degrees=True).as_matrix()  # jumps at frame 25, stays off
    step = step_errors_deg(R_est, R_true)
    assert np.isnan(step[0]) and abs(step[25] - 40.0) < 1.5
    assert np.nanmax(step[1:25]) < 1e-6
    assert np.nanmax(step[26:]) < 1.5  # the offset turns later steps' axes, not their size
    summary = error_summary(attitude_errors(R_est, np.tile(np.eye(3) * 1e-4, (40, 1, 1)), np.ones(40, bool), R_true))
    assert summary["frame_jumps_over_10deg"] == 1
    assert summary["frames_are_over_10deg"] >= 15  # frames left 40 deg off by one jump: ARE counts them all
