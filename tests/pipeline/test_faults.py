"""Faults mid-stream through the real pipeline (solver, mekf, file sinks): IMU and camera stalls, frame
gaps, blank frames, a saturated gyro, a camera that disconnects (fake OAK device, truncated video)
and Ctrl-C on a real `uareme-fusion run` process. The estimate must degrade visibly (covariance
grows, status flags say why) and recover (tilt error back within bounds after the fault); the
outputs written before a stop stay complete and parseable."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from unittest import mock

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.drivers.base import ImuBatch, Source
from uareme_fusion.drivers.simulated import SimulatedSource
from uareme_fusion.pipeline import RunConfig
from uareme_fusion.pipeline.session import run_source
from uareme_fusion.rotations import tilt_error_deg, up_in_camera
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.types import NormalMap, Status
from helpers import FakeImgFrame, assert_outputs_complete, packets  # pytest puts tests/ on sys.path

SECONDS = 8.0
FAULT = (3.0, 5.0)
"""The fault window of the scenarios, s."""
RECOVERED_TILT_DEG = 0.5
"""Tilt error every estimate must be back under 0.5 s after a fault (the clean run stays under 0.1)."""


def _inside(t_s, window) -> np.ndarray:
    t_s = np.asarray(t_s, float)
    return np.zeros(t_s.shape, bool) if window is None else (t_s >= window[0]) & (t_s < window[1])


class FaultySource(Source):
    """`sim:room` (normals only, 2 deg noise, 200 Hz IMU) with faults injected in time windows:
    `imu_gap` drops IMU samples, `frame_gap` drops frames, `blank` zeroes the frames' confidence (black
    frames: no valid normals), `stuck_gyro` pins the gyro at full scale (a shock), `gyro_clip_rad_s`
    clips every gyro reading like a sensor of that range."""

    def __init__(self, imu_gap=None, frame_gap=None, blank=None, stuck_gyro=None, gyro_clip_rad_s=None,
                 stuck_rad_s=34.9):
        self.sim = SimulatedSource("room", seconds=SECONDS, render=False, normals_noise_deg=2.0)
        self.info = self.sim.info
        self.imu_gap, self.frame_gap, self.blank, self.stuck_gyro = imu_gap, frame_gap, blank, stuck_gyro
        self.gyro_clip_rad_s, self.stuck_rad_s = gyro_clip_rad_s, stuck_rad_s

    def ground_truth(self):
        return self.sim.ground_truth()

    def true_R_wc(self, t_s):
        return self.sim.trajectory.sample(np.asarray(t_s, float)).R_wc

    def events(self):
        for ev in self.sim.events():
            if isinstance(ev, ImuBatch):
                gyro = ev.gyro_rad_s.copy()
                if self.gyro_clip_rad_s is not None:
                    np.clip(gyro, -self.gyro_clip_rad_s, self.gyro_clip_rad_s, out=gyro)
                gyro[_inside(ev.t_s, self.stuck_gyro)] = self.stuck_rad_s
                keep = ~_inside(ev.t_s, self.imu_gap)
                if keep.any():
                    yield ImuBatch(ev.t_s[keep], gyro[keep], ev.accel_m_s2[keep])
            elif not _inside(ev.t_s, self.frame_gap):
                if _inside(ev.t_s, self.blank):
                    ev = dataclasses.replace(ev, normals=NormalMap(ev.normals.normals, np.zeros_like(ev.normals.kappa),
                                                                   t_s=ev.t_s))
                yield ev


@dataclasses.dataclass
class Trace:
    t: np.ndarray
    std_deg: np.ndarray
    """sqrt of the covariance's trace, degrees."""
    status: np.ndarray
    tilt_deg: np.ndarray
    summary: dict

    def flagged(self, flag: Status) -> np.ndarray:
        return (self.status & int(flag)) != 0

    def at(self, t_s: float) -> int:
        """Index of the first estimate at or after `t_s`."""
        return int(np.searchsorted(self.t, t_s - 1e-9))


def run_faulty(tmp_path, source: FaultySource, **mekf) -> Trace:
    rows = []

    def on_result(result, stats):
        est = result.estimate
        rows.append((result.t_s, np.trace(est.cov), int(est.status), est.R_wc))

    cfg = RunConfig(normals="source", mekf_preset="building", mekf=mekf)
    summary = run_source(source, tmp_path, cfg, on_result=on_result)
    t = np.array([r[0] for r in rows])
    R = np.array([r[3] for r in rows])
    tilt = tilt_error_deg(up_in_camera(R), up_in_camera(source.true_R_wc(t)))
    return Trace(t, np.degrees(np.sqrt([r[1] for r in rows])), np.array([r[2] for r in rows]), tilt, summary)


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Trace:
    return run_faulty(tmp_path_factory.mktemp("clean"), FaultySource())


@pytest.mark.slow
def test_clean_run_is_the_reference(clean):
    assert clean.summary["stopped"] == "end" and clean.summary["frames"] == 240
    assert clean.tilt_deg[clean.at(1.0):].max() < 0.1
    assert not clean.flagged(Status.IMU_GAP | Status.GYRO_SATURATED | Status.VISUAL_MISSING).any()


@pytest.mark.slow
def test_camera_and_imu_stall_flags_the_gap_inflates_and_recovers(tmp_path, clean):
    """Both streams stop for 2 s (a USB hiccup): the first estimate after it says IMU_GAP, with the
    attitude uncertainty of an unknown rotation over the gap, and the error is back at once."""
    trace = run_faulty(tmp_path, FaultySource(imu_gap=FAULT, frame_gap=FAULT))
    assert not _inside(trace.t, FAULT).any()  # no estimate inside the stall
    k = trace.at(FAULT[1])
    assert trace.flagged(Status.IMU_GAP)[k] and trace.summary["status_counts"]["IMU_GAP"] == 1
    assert trace.std_deg[k] > 2.5 * trace.std_deg[k - 1]
    assert trace.tilt_deg[trace.at(FAULT[1] + 0.5):].max() < RECOVERED_TILT_DEG
    assert trace.std_deg[trace.at(FAULT[1] + 1.0)] < 1.3 * clean.std_deg[clean.at(FAULT[1] + 1.0)]


@pytest.mark.slow
def test_frame_gap_is_bridged_by_the_gyro(tmp_path, clean):
    """No frames for 2 s while the IMU runs: the gyro carries the attitude (covariance grows a little),
    the first frame back tightens it again."""
    trace = run_faulty(tmp_path, FaultySource(frame_gap=FAULT))
    k = trace.at(FAULT[1])
    assert trace.t[k - 1] < FAULT[0] and trace.std_deg[k] > 1.2 * trace.std_deg[k - 1]
    assert trace.tilt_deg[k] < RECOVERED_TILT_DEG  # the gyro bridged the gap
    assert trace.std_deg[trace.at(FAULT[1] + 1.0)] < trace.std_deg[k]
    assert trace.tilt_deg[trace.at(1.0):].max() < RECOVERED_TILT_DEG


def test_blank_frames_are_flagged_and_the_covariance_grows_until_they_end(tmp_path):
    trace = run_faulty(tmp_path, FaultySource(blank=FAULT))
    during = _inside(trace.t, FAULT)
    assert trace.flagged(Status.VISUAL_MISSING)[during].all() and not trace.flagged(Status.VISUAL_MISSING)[~during].any()
    assert trace.summary["frames_without_visual"] == during.sum() == 60
    std = trace.std_deg[during]
    assert np.all(np.diff(std) > 0) and std[-1] > 1.4 * std[0]  # gyro only: uncertainty grows every frame
    assert trace.tilt_deg[during].max() < RECOVERED_TILT_DEG  # ...while the gyro keeps the attitude
    after = trace.at(FAULT[1] + 0.5)
    assert trace.std_deg[after] < 0.8 * std[-1] and trace.tilt_deg[after:].max() < RECOVERED_TILT_DEG


@pytest.mark.slow
def test_gyro_saturating_in_fast_turns_is_flagged_and_inflated(tmp_path, clean):
    """A gyro of 0.9 rad/s range in a walk turning at up to 1.4 rad/s: readings clip; the estimates
    over clipped samples say GYRO_SATURATED with a larger covariance, and the vision keeps tilt right."""
    trace = run_faulty(tmp_path, FaultySource(gyro_clip_rad_s=0.9), gyro_range_rad_s=0.9)
    saturated = trace.flagged(Status.GYRO_SATURATED)
    late = trace.t > 1.5
    assert saturated[late].sum() > 30 and (~saturated[late]).sum() > 30  # the walk's fast turns only
    assert np.median(trace.std_deg[late & saturated]) > 1.4 * np.median(trace.std_deg[late & ~saturated])
    assert trace.tilt_deg[trace.at(1.0):].max() < 2 * RECOVERED_TILT_DEG
    assert trace.tilt_deg[-30:].max() < RECOVERED_TILT_DEG


def test_gyro_stuck_at_full_scale_for_a_shock_recovers(tmp_path):
    """0.2 s of full-scale readings (a knock): flagged, the covariance grows by the unknown rate while the
    last unsaturated reading is held (the pinned one is not integrated), so tilt never leaves the bound."""
    shock = (3.0, 3.2)
    trace = run_faulty(tmp_path, FaultySource(stuck_gyro=shock))
    k, before = trace.at(shock[1]), trace.at(shock[0]) - 1
    assert trace.flagged(Status.GYRO_SATURATED)[before + 1:k + 1].all()
    assert not trace.flagged(Status.GYRO_SATURATED)[:before + 1].any()
    assert trace.std_deg[k] > 2.5 * trace.std_deg[before]
    assert trace.tilt_deg[trace.at(1.0):].max() < RECOVERED_TILT_DEG


def test_imu_gap_while_frames_continue_is_flagged_and_recovers(tmp_path):
    trace = run_faulty(tmp_path, FaultySource(imu_gap=FAULT))
    late = _inside(trace.t, (FAULT[0] + 0.1 + 1 / 30, FAULT[1]))  # past imu_gap_limit_s, before the IMU is back
    assert trace.flagged(Status.IMU_GAP)[late].all() and trace.flagged(Status.IMU_GAP).sum() <= late.sum() + 2
    assert not trace.flagged(Status.VISUAL_REJECTED | Status.REINITIALISED)[trace.at(FAULT[0]):].any()
    assert trace.tilt_deg[trace.at(FAULT[1] + 1.0):].max() < RECOVERED_TILT_DEG


def test_gyro_stuck_for_half_a_second_recovers(tmp_path):
    trace = run_faulty(tmp_path, FaultySource(stuck_gyro=(3.0, 3.5)))
    assert trace.tilt_deg[trace.at(6.0):].max() < 5.0


# ----------------------------------------------------------------- cameras that go away, via the CLI
runner = CliRunner()


def normal_maps(folder, n: int):
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(n):
        nm = manhattan_normal_map(np.eye(3), rng, height=12, width=16, noise_deg=3.0)
        np.savez(folder / f"{i:06d}.npz", normals=nm.normals, kappa=nm.kappa)
    return folder





def fake_oak_device(frames_before_disconnect: int, size=(12, 16)):
    """A fake `depthai` module: an OAK whose pipeline delivers frames at 30 Hz with 200 Hz IMU packets,
    then stops running (the cable pulled) after `frames_before_disconnect` frames."""
    dai = mock.MagicMock(name="depthai")
    device = dai.Device.return_value
    device.readCalibration.return_value.getCameraIntrinsics.return_value = [[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]]
    device.readCalibration.return_value.getImuToCameraExtrinsics.return_value = np.eye(4).tolist()
    pipeline = dai.Pipeline.return_value
    sent = {"frames": 0, "imu": 0}
    bgr = np.full((*size, 3), 90, np.uint8)

    def next_frame():
        k = sent["frames"]
        sent["frames"] += 1
        return FakeImgFrame(bgr, k / 30.0)

    def next_imu():
        k = sent["imu"]
        sent["imu"] += 1
        msg = mock.Mock()
        msg.packets = packets((k + np.arange(1, 8) / 7.0) / 30.0)  # (k/30, (k+1)/30]
        for p in msg.packets:  # at rest, camera y down: the accelerometer reads up = -y
            p.gyroscope.x = p.gyroscope.y = p.gyroscope.z = 0.0
            p.acceleroMeter.x, p.acceleroMeter.y, p.acceleroMeter.z = 0.0, -9.81, 0.0
        return msg

    frames_q = pipeline.create.return_value.build.return_value.requestOutput.return_value.createOutputQueue.return_value
    frames_q.tryGet.side_effect = next_frame
    pipeline.create.return_value.out.createOutputQueue.return_value.tryGet.side_effect = next_imu
    pipeline.isRunning.side_effect = lambda: sent["frames"] < frames_before_disconnect
    return dai


def test_oak_that_disconnects_mid_run_exits_1_with_outputs_kept(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "depthai", fake_oak_device(frames_before_disconnect=12))
    maps = normal_maps(tmp_path / "maps", 12)
    result = runner.invoke(app, ["run", "oak", "--normals", str(maps), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error")]
    assert len(errors) == 1 and "Traceback" not in result.output
    assert errors[0].startswith("error: oak: device disconnected (pipeline stopped) (outputs so far kept in")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert 10 <= summary["frames"] <= 12  # what the frame/IMU sync had released when the device went
    assert_outputs_complete(tmp_path / "out", summary["frames"], "source_error")
    assert summary["imu_samples"] > 60 and summary["source_info"]["has_imu"]


@pytest.mark.slow
def test_truncated_video_exits_1_naming_the_frame_with_outputs_kept(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (64, 48))
    rng = np.random.default_rng(0)
    for _ in range(30):
        writer.write(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
    writer.release()
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.6)])  # the copy stopped part way
    maps = normal_maps(tmp_path / "maps", 30)
    result = runner.invoke(app, ["run", str(path), "--normals", str(maps), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error")]
    assert len(errors) == 1 and "Traceback" not in result.output
    assert "clip.avi: decoding stopped at frame 18 of 30 (truncated or corrupt file)" in errors[0]
    assert_outputs_complete(tmp_path / "out", 18, "source_error")


def default_sigint() -> None:
    """In the child before it starts: SIGINT back to its default, so that Python turns it into
    KeyboardInterrupt even when the test runner was started with SIGINT ignored (nohup, CI)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.slow
def test_ctrl_c_on_a_real_run_exits_130_with_complete_outputs(tmp_path):
    """SIGINT to `uareme-fusion run sim:room` (rendered, about 300 frames) once it has written a few
    estimates: exit status 130, and every output complete and parseable."""
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "uareme_fusion", "run", "sim:room", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)
    trajectory = out / "trajectory.tum"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if trajectory.is_file() and trajectory.read_text().count("\n") >= 6:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "interrupted by the user (Ctrl-C)" in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert 5 <= summary["frames"] < 300
    assert_outputs_complete(out, summary["frames"], "interrupted")
    assert os.path.getsize(out / "estimates.csv") > 0
