"""Real data (skipped without the fetched TUM fr1 rpy folder): `eval EVAL_SPLIT --normals depth --backend
single`, the figure issue 29 asks of depth, with the TUM RGB-D ground-truth clock default
(`formats.tum.TUM_RGBD_GT_TIME_OFFSET_S`, estimated on the train split only)."""

import pytest

from uareme_fusion.formats.fetched import tum_rpy_root, tum_rpy_split
from uareme_fusion.formats.tum import TUM_RGBD_GT_TIME_OFFSET_S
from uareme_fusion.pipeline import RunConfig
from uareme_fusion.pipeline.session import run_to_folder


@pytest.mark.slow
def test_depth_on_the_tum_evaluation_frames_reaches_the_goal(tmp_path):
    root = tum_rpy_root()
    if root is None:
        pytest.skip("the fetched TUM freiburg1_rpy folder is not there (formats.fetched.tum_rpy_root)")
    folder = tum_rpy_split(root, "eval", tmp_path / "split")
    summary = run_to_folder(folder, tmp_path / "run", RunConfig(normals="depth", backend="single"), evaluate=True)
    assert summary["frames_scored"] >= 200
    assert any(f"{TUM_RGBD_GT_TIME_OFFSET_S * 1000:+.0f} ms" in note for note in summary["notes"])
    assert summary["are_deg"]["mean"] <= 4.0  # 4.72 with the mocap stamps as recorded
    assert 1.0 <= summary["nees"]["mean"] <= 6.0
