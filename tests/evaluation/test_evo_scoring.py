"""The README's evo command scores a run's orientation-only trajectory.tum (issue 16).

Our trajectory has no positions (all 0), so evo's default Umeyama alignment (`-a`) is degenerate;
`evo_ape tum GT trajectory.tum -r angle_deg --align_origin` aligns the first poses and scores the
rotation angle. The test checks evo's figures against the same error computed here from the files.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import zipfile

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.formats.tum import read_tum_trajectory

EVO_APE = shutil.which("evo_ape")
README_COMMAND = "evo_ape tum {gt} {traj} -r angle_deg --align_origin"


def _origin_aligned_angle_deg(gt_path, traj_path) -> np.ndarray:
    """Per-pose angle of `R_gt^T (R_gt0 R_est0^T) R_est` at the trajectory's stamps (exact matches)."""
    (t_gt, _, q_gt), (t_est, _, q_est) = read_tum_trajectory(gt_path), read_tum_trajectory(traj_path)
    index = {round(t, 6): k for k, t in enumerate(t_gt)}
    pairs = [(index[round(t, 6)], k) for k, t in enumerate(t_est) if round(t, 6) in index]
    R_gt = Rotation.from_quat(q_gt[[g for g, _ in pairs]])
    R_est = Rotation.from_quat(q_est[[e for _, e in pairs]])
    align = R_gt[0] * R_est[0].inv()
    return np.degrees((R_gt.inv() * align * R_est).magnitude())


@pytest.mark.slow
@pytest.mark.skipif(EVO_APE is None, reason="evo is not installed (pip install evo, or the 'bench' extra)")
def test_readme_evo_command_scores_a_run(tmp_path):
    runner = CliRunner()
    seq, out = tmp_path / "seq", tmp_path / "out"
    for args in (["simulate", "room", "--frames", "45", "--size", "96x72", "--out", str(seq)],
                 ["run", str(seq), "--out", str(out)]):
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
    gt, traj, saved = seq / "groundtruth.txt", out / "trajectory.tum", tmp_path / "ape.zip"
    command = README_COMMAND.format(gt=gt, traj=traj).split() + ["--save_results", str(saved), "--no_warnings"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    with zipfile.ZipFile(saved) as zf:
        stats = json.loads(zf.read("stats.json"))
    ours = _origin_aligned_angle_deg(gt, traj)
    assert len(ours) == 45
    assert stats["mean"] == pytest.approx(ours.mean(), abs=1e-3)
    assert stats["max"] == pytest.approx(ours.max(), abs=1e-3)
    assert stats["mean"] < 10.0  # a working run on exact normals
