"""`run --rerun FILE.rrd` writes a recording that reads back with what the viewer shows (issue 16)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.sinks.rerun_file import roll_pitch_deg

rerun = pytest.importorskip("rerun", reason="rerun-sdk is not installed (the 'viewer' extra)")


def _columns(path) -> dict:
    """{entity path: {column name: values of every row, in file order}} of a .rrd file."""
    from rerun.chunk import RrdReader

    columns: dict[str, dict[str, list]] = {}
    for chunk in RrdReader(str(path)).store().stream().to_chunks():
        batch = chunk.to_record_batch()
        entity = columns.setdefault(str(chunk.entity_path), {})
        for name in batch.schema.names:
            entity.setdefault(name, []).extend(batch.column(name).to_pylist())
    return columns


def test_roll_and_pitch_of_level_and_tilted_cameras():
    assert roll_pitch_deg([0, -1, 0]) == pytest.approx((0.0, 0.0))
    # camera pitched up by 20 deg: world up leans towards the optical axis (+z)
    up = [0.0, -np.cos(np.radians(20)), np.sin(np.radians(20))]
    assert roll_pitch_deg(up) == pytest.approx((0.0, 20.0))
    assert roll_pitch_deg([np.sin(0.3), -np.cos(0.3), 0])[0] == pytest.approx(np.degrees(0.3))


@pytest.mark.slow
def test_run_writes_a_recording_that_reads_back(tmp_path):
    rrd = tmp_path / "view" / "run.rrd"
    result = CliRunner().invoke(app, ["run", "sim:room", "--max-frames", "12", "--out", str(tmp_path / "out"),
                                      "--rerun", str(rrd)])
    assert result.exit_code == 0, result.output
    assert rrd.is_file()
    columns = _columns(rrd)
    for entity in ("/world/camera", "/world/camera/image", "/world/camera/normals", "/world/camera/confidence",
                   "/plots/roll_deg", "/plots/pitch_deg", "/plots/std_deg/x", "/plots/status", "/status"):
        assert entity in columns, f"{entity} missing; have {sorted(columns)}"
    rolls = np.array([v[0] for v in columns["/plots/roll_deg"]["Scalars:scalars"]])
    assert len(rolls) == 12
    images = [b for b in columns["/world/camera/image"]["Image:buffer"] if b is not None]
    assert len(images) == 12 and len(images[0][0]) == 320 * 240 * 3  # the overlay, RGB, at frame size
    # the logged camera rotation is the trajectory's R_wc, frame by frame
    traj = np.loadtxt(tmp_path / "out" / "trajectory.tum")
    quats = [q for q in columns["/world/camera"]["Transform3D:quaternion"] if q is not None]
    assert len(quats) == 12
    logged = Rotation.from_quat(np.array([q[0] for q in quats]))
    np.testing.assert_allclose((logged.inv() * Rotation.from_quat(traj[:, 4:8])).magnitude(), 0.0, atol=1e-5)
    # roll over time matches the estimates' up vector
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["frames"] == 12
    up_c = Rotation.from_quat(traj[:, 4:8]).inv().apply([0, 0, 1])
    np.testing.assert_allclose(rolls, [roll_pitch_deg(u)[0] for u in up_c], atol=1e-3)


def test_rerun_needs_an_rrd_name(tmp_path):
    result = CliRunner().invoke(app, ["run", "sim:room", "--max-frames", "2", "--out", str(tmp_path / "out"),
                                      "--rerun", str(tmp_path / "run.mp4")])
    assert result.exit_code == 2 and ".rrd" in result.output
