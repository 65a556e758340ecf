"""Helpers shared by several test modules (test modules import from here, never from each other),
and the path of the development data (`../shared/data`; tests take it through conftest's
`shared_data` fixture)."""

from __future__ import annotations

import contextlib
import csv
import json
import os
import subprocess
from types import SimpleNamespace

import struct
import zlib
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.sinks.estimate_files import ESTIMATE_COLUMNS
from uareme_fusion.drivers.base import GroundTruth, ImuBatch, Source, SourceInfo
from uareme_fusion.errors import SourceError
from uareme_fusion.sim.imu import simulate_imu
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.sim.trajectory import make_trajectory
from uareme_fusion.types import Frame

SHARED_DATA = Path(os.environ.get("UAREME_SHARED_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")
"""`../shared/data` beside the repository, or `$UAREME_SHARED_DATA` (real sequences for measurement; absent in
some checkouts)."""


def shared_data_or_skip() -> Path:
    """`SHARED_DATA`, or a skip of the calling test when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"development data not found at {SHARED_DATA}")
    return SHARED_DATA


def png_bytes(width: int, height: int, colour_type: int = 2, bit_depth: int = 8, rows: int = 2) -> bytes:
    """A PNG whose IHDR declares width x height but whose data holds only `rows` rows."""

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    idat = zlib.compress(b"\x00" * ((min(width, 64) * 3 + 1) * rows))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


class FakeImgFrame:
    """What the driver uses of depthai.ImgFrame."""

    def __init__(self, image, t_s):
        self.image, self.t_s = image, t_s

    def getCvFrame(self):
        return self.image

    def getFrame(self):
        return self.image

    def getTimestampDevice(self):
        return timedelta(seconds=self.t_s)


class FakeReport:
    def __init__(self, xyz, t_s):
        self.x, self.y, self.z = xyz
        self.t_s = t_s

    def getTimestampDevice(self):
        return timedelta(seconds=self.t_s)


class FakePacket:
    def __init__(self, t_s, gyro, accel, accel_t_s=None):
        self.gyroscope = FakeReport(gyro, t_s)
        self.acceleroMeter = FakeReport(accel, t_s if accel_t_s is None else accel_t_s)


def packets(t_s, seed=0):
    rng = np.random.default_rng(seed)
    return [FakePacket(t, rng.normal(size=3), rng.normal(size=3) + [0, 0, 9.81]) for t in t_s]


class WalkSource(Source):
    """A simulated walk: exact-ish normals (10 deg noise) per frame, 200 Hz IMU, ground truth."""

    def __init__(self, seconds=6.0, fps=15.0, seed=0, imu=True, fail_at=None, interrupt_at=None, blank=()):
        self.traj = make_trajectory("walk", seconds, seed=seed)
        self.t_frame = np.arange(0.0, seconds, 1.0 / fps)
        self.imu = simulate_imu(self.traj, rate_hz=200.0, seed=seed) if imu else None
        self.seed, self.fail_at, self.interrupt_at, self.blank = seed, fail_at, interrupt_at, set(blank)
        self.info = SourceInfo(name="walk-test", n_frames=len(self.t_frame), fps=fps, has_imu=imu)
        self.closed = False

    def events(self):
        rng = np.random.default_rng(self.seed)
        R_cm = self.traj.R_cm(self.t_frame)
        start = 0
        for k, t in enumerate(self.t_frame):
            if k == self.fail_at:
                raise SourceError(f"walk-test: camera disconnected at frame {k}")
            if k == self.interrupt_at:
                raise KeyboardInterrupt
            if self.imu is not None:
                t_imu, gyro, accel = self.imu
                end = int(np.searchsorted(t_imu, t, side="right"))
                if end > start:
                    yield ImuBatch(t_imu[start:end], gyro[start:end], accel[start:end])
                start = end
            nm = manhattan_normal_map(R_cm[k], rng, 60, 80, noise_deg=10.0, correlation_px=3.0)
            if k in self.blank:
                nm = type(nm)(nm.normals, np.zeros_like(nm.kappa))
            yield Frame(float(t), index=k, normals=nm)

    def ground_truth(self):
        return GroundTruth(self.t_frame, self.traj.sample(self.t_frame).R_wc, gravity_aligned=True)

    def close(self):
        self.closed = True


REPO = Path(__file__).resolve().parents[1]


def cli(*args, cwd: Path | None = None) -> SimpleNamespace:
    """`uareme-fusion ARGS` in this process (typer's runner: the same error boundary as the console
    script); `returncode`, `stdout`, `stderr` as from a subprocess."""
    with contextlib.chdir(cwd or Path.cwd()):
        result = CliRunner().invoke(app, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return SimpleNamespace(returncode=result.exit_code, stdout=result.stdout, stderr=result.stderr)


def subprocess_env() -> dict:
    """The environment for `python -m uareme_fusion` in a child: this checkout first on the path, one thread."""
    return {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}


def error_lines(proc) -> list[str]:
    assert "Traceback" not in proc.stderr, proc.stderr
    return [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]


def assert_outputs_complete(out, frames: int, stopped: str) -> dict:
    """trajectory.tum and estimates.csv hold `frames` whole rows; summary.json says why it stopped."""
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] == stopped and summary["frames"] == frames and summary["estimates"] == frames
    lines = [ln for ln in (out / "trajectory.tum").read_text().splitlines() if not ln.startswith("#")]
    rows = np.array([[float(v) for v in ln.split()] for ln in lines]).reshape(-1, 8)
    assert len(rows) == frames and np.allclose(np.linalg.norm(rows[:, 4:], axis=1), 1.0)
    assert np.all(np.diff(rows[:, 0]) > 0)
    with open(out / "estimates.csv", newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0] == ESTIMATE_COLUMNS and len(table) == frames + 1
    assert all(len(r) == len(ESTIMATE_COLUMNS) for r in table[1:])
    return summary


@contextlib.contextmanager
def tmpfs(mount: Path, options: str):
    """A tmpfs mounted at `mount` (created) with mount `options` (e.g. "size=200k"), unmounted after;
    skips the calling test where the machine does not allow mounting one (needs root)."""
    mount.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mount)],
                              capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"cannot mount a tmpfs here ({exc})")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], capture_output=True, timeout=10)
