"""The streaming pipeline on an in-memory source: outputs, evaluation, early stops, bounded state."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from uareme_fusion.backends.mekf import Mekf
from uareme_fusion.drivers.base import ImuBatch, SourceInfo
from uareme_fusion.errors import InputError
from uareme_fusion.pipeline import RunConfig
from uareme_fusion.pipeline.session import run_source
from uareme_fusion.rotations import matrix_from_quat_xyzw

from helpers import WalkSource  # pytest puts tests/ on sys.path


def read_tum(path):
    rows = np.loadtxt(path, comments="#")
    return rows[:, 0], matrix_from_quat_xyzw(rows[:, 4:8])


def test_run_writes_trajectory_csv_and_summary_that_agree(tmp_path):
    src = WalkSource()
    summary = run_source(src, tmp_path, RunConfig(backend="mekf", mekf_preset="building"), evaluate=True)
    t, R = read_tum(tmp_path / "trajectory.tum")
    assert len(t) == len(src.t_frame) == summary["frames"] == summary["estimates"]
    np.testing.assert_allclose(t, src.t_frame, atol=1e-9)
    with open(tmp_path / "estimates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(t)
    up = np.array([[float(r["up_x"]), float(r["up_y"]), float(r["up_z"])] for r in rows])
    np.testing.assert_allclose(up, R.transpose(0, 2, 1)[:, :, 2], atol=1e-6)  # up_c = R_wc^T z
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["stopped"] == "end" and on_disk["normals"] == "auto (source)"
    # The fused walk is accurate and consistent against the simulator's truth.
    assert on_disk["are_deg"]["mean"] < 1.5 and on_disk["tilt_deg"]["p95"] < 2.0
    assert 0.3 < on_disk["nees"]["mean"] < 10
    assert set(on_disk["timing_ms"]) >= {"normals", "solver", "backend", "total"} and on_disk["fps"] > 0
    assert on_disk["imu_samples"] > 1000


def test_backend_warms_up_before_the_first_event(tmp_path, monkeypatch):
    """The pipeline has the backend load its kernels before it reads the source (a live stream's first
    frames would wait for them), telling it whether IMU samples and frames will come; the time is reported."""
    calls = []
    monkeypatch.setattr(Mekf, "warm_up", lambda self, *has: calls.append(("warm_up", *has)))
    for imu in (True, False):
        src = WalkSource(seconds=1.0, imu=imu)

        def events(events=src.events):
            calls.append("first event")  # runs at the first `next`
            yield from events()
        monkeypatch.setattr(src, "events", events)
        summary = run_source(src, tmp_path, RunConfig(backend="mekf"))
        assert calls == [("warm_up", imu, True), "first event"] and summary["warm_up_s"] >= 0.0
        calls.clear()


def test_blank_frames_give_no_visual_and_are_counted(tmp_path):
    src = WalkSource(blank=(10, 11, 12))
    summary = run_source(src, tmp_path, RunConfig(backend="mekf", mekf_preset="building"), evaluate=True)
    assert summary["frames_without_visual"] == 3
    assert summary["status_counts"].get("VISUAL_MISSING", 0) == 3
    assert summary["are_deg"]["max"] < 5.0


@pytest.mark.parametrize("kind,stopped", [("fail", "source_error"), ("interrupt", "interrupted")])
def test_stops_mid_stream_keep_outputs_complete(tmp_path, kind, stopped):
    src = WalkSource(fail_at=30 if kind == "fail" else None, interrupt_at=30 if kind == "interrupt" else None)
    summary = run_source(src, tmp_path, RunConfig(backend="single"))
    assert summary["stopped"] == stopped and summary["frames"] == 30
    t, R = read_tum(tmp_path / "trajectory.tum")
    assert len(t) == 30 and np.allclose(np.linalg.det(R), 1.0)
    with open(tmp_path / "estimates.csv") as fh:
        assert len(list(csv.DictReader(fh))) == 30
    assert json.loads((tmp_path / "summary.json").read_text())["error"]


def test_max_frames_and_every_backend(tmp_path):
    for backend in ("single", "smoother", "mekf"):
        out = tmp_path / backend
        out.mkdir()
        summary = run_source(WalkSource(seconds=3.0), out, RunConfig(backend=backend, max_frames=20), evaluate=True)
        assert summary["stopped"] == "max_frames" and summary["estimates"] == 20
        assert summary["are_deg"]["max"] < 5.0, backend


def test_imu_only_source_gives_one_estimate_per_batch(tmp_path):
    class ImuOnly(WalkSource):
        def __init__(self):
            super().__init__(seconds=4.0)
            self.info = SourceInfo(name="imu-only", has_frames=False, has_imu=True)

        def events(self):
            for ev in super().events():
                if isinstance(ev, ImuBatch):
                    yield ev

    summary = run_source(ImuOnly(), tmp_path, RunConfig(backend="mekf", mekf_preset="building"), evaluate=True)
    assert summary["frames"] == 0 and summary["estimates"] > 50
    # Accelerometer only: the walk circles, so a steady centripetal acceleration tilts "up" by ~2.5 deg.
    assert summary["tilt_deg"]["p95"] < 4.0


def test_evaluate_needs_ground_truth(tmp_path):
    class NoTruth(WalkSource):
        def ground_truth(self):
            return None

    with pytest.raises(InputError, match="walk-test: this source has no ground truth"):
        run_source(NoTruth(), tmp_path, RunConfig(), evaluate=True)


def test_depth_normals_need_depth(tmp_path):
    with pytest.raises(InputError, match="--normals depth needs a depth map"):
        run_source(WalkSource(), tmp_path, RunConfig(normals="depth"))
