"""The last reliability gaps of issue 28 (found by running the real CLI on bad input): each ends in one
line naming the file or option, a non-zero exit where something failed, and no stray folder."""

from __future__ import annotations

import io
import json
import os
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from rich.console import Console

import uareme_fusion.demo as demo_module
import uareme_fusion.io.paths as paths_module
import uareme_fusion.io.safe_files as safe_files
from uareme_fusion.config import load_config
from uareme_fusion.drivers import open_source
from uareme_fusion.errors import ConfigError, OutputError
from uareme_fusion.pipeline import RunConfig
from uareme_fusion.pipeline.session import run_source
from uareme_fusion.sim.dataset import INCOMPLETE_MARKER, SequenceOptions, write_sequence
from helpers import cli, error_lines


# ------------------------------------------------------------------------------ --config on a named pipe
def test_a_silent_fifo_as_config_is_refused_in_time(tmp_path, monkeypatch):
    fifo = tmp_path / "run.yaml"
    os.mkfifo(fifo)
    monkeypatch.setattr(paths_module, "PIPE_WAIT_S", 0.2)
    with pytest.raises(ConfigError, match=r"run.yaml: is a pipe \(FIFO\) and nothing was written to it within 0.2 s"):
        load_config(fifo, RunConfig)
    proc = cli("run", "sim:room", "--config", fifo, "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: Cannot read config file {fifo}: is a pipe (FIFO) and nothing was written "
                                 "to it within 0.2 s"]
    assert not (tmp_path / "out").exists()


def test_a_fifo_config_with_a_writer_is_read(tmp_path):
    fifo = tmp_path / "run.yaml"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_text("backend: single\nmax_frames: 7\n"), daemon=True)
    writer.start()
    cfg = load_config(fifo, RunConfig)
    writer.join(timeout=10)
    assert cfg.backend == "single" and cfg.max_frames == 7


# ------------------------------------------------------------------------------ Ctrl-C during simulate
def test_an_interrupted_simulate_leaves_a_folder_that_says_so(tmp_path):
    out = tmp_path / "sim"

    def stop_after_three(done, total):
        if done == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_sequence("room", out, SequenceOptions(frames=20, width=64, height=48), progress=stop_after_three)
    marker = json.loads((out / INCOMPLETE_MARKER).read_text())
    assert marker["frames"] == 20 and "--force" in marker["note"]
    proc = cli("run", out, "--out", tmp_path / "run")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {out}: is an interrupted 'simulate' (3 of 20 frames written, no index or "
                                 f"IMU files); write it again with 'uareme-fusion simulate ... --out {out} --force'"]
    assert not (tmp_path / "run").exists()
    # finished, the folder loses its marker and runs
    proc = cli("simulate", "room", "--frames", 4, "--size", "64x48", "--out", out, "--force")
    assert proc.returncode == 0, proc.stderr
    assert not (out / INCOMPLETE_MARKER).exists()
    with open_source(str(out)) as src:
        assert src.info.n_frames == 4


# ------------------------------------------------------------------------------ errors that name the file
def test_image_of_one_pixel_and_a_map_of_nan_normals_name_their_file(tmp_path):
    cv2.imwrite(str(tmp_path / "one.png"), np.zeros((1, 1, 3), np.uint8))
    proc = cli("image", tmp_path / "one.png")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {tmp_path / 'one.png'}: image of 1x1 pixels is too small (at least 8x8)"]
    np.savez(tmp_path / "nan.npz", normals=np.full((20, 20, 3), np.nan, np.float32),
             kappa=np.ones((20, 20), np.float32))
    proc = cli("solve", tmp_path / "nan.npz")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {tmp_path / 'nan.npz'}: No valid normals in a map of shape (20, 20, 3): "
                                 "all 400 pixels are NaN, zero-length, or have kappa <= 0"]


def test_a_simulated_source_names_fps_not_frames(tmp_path):
    proc = cli("run", "sim:room", "--fps", "1e9", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert error_lines(proc) == ["error: --fps must be between 1 and 1000, got 1000000000.0"]


# ------------------------------------------------------------------------------ a report that cannot be written
@pytest.fixture
def no_rename(monkeypatch):
    """Renaming a temporary file onto a device would replace the device node (as root): forbidden here."""
    def refuse(tmp, path):
        raise AssertionError(f"{path} would have been replaced by a renamed file")

    monkeypatch.setattr(safe_files, "publish", refuse)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")
def test_a_report_to_dev_full_is_an_error(tmp_path, no_rename):
    with pytest.raises(OutputError, match=r"/dev/full: could not be written \(No space left on device\)"):
        safe_files.write_text_atomic(Path("/dev/full"), "{}\n")
    proc = cli("bench", "solver", "--repeats", 5, "--json", "/dev/full")
    assert proc.returncode == 1
    assert error_lines(proc) == ["error: /dev/full: could not be written (No space left on device)"]


def test_a_report_to_a_pipe_is_written_into_it(tmp_path, no_rename):
    fifo = tmp_path / "report.fifo"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_text()), daemon=True)
    reader.start()
    safe_files.write_text_atomic(fifo, '{"ok": 1}\n')
    reader.join(timeout=10)
    assert received == ['{"ok": 1}\n'] and safe_files.is_stream(fifo)


# ------------------------------------------------------------------------------ a newcomer's first hour
def test_a_failed_run_removes_the_folders_it_created(tmp_path):
    proc = cli("run", tmp_path / "missing.mp4", "--out", tmp_path / "a" / "b")
    assert proc.returncode == 2 and "no such file or folder" in error_lines(proc)[0]
    assert not (tmp_path / "a").exists()
    (tmp_path / "mine").mkdir()  # a folder the user made is theirs: kept
    proc = cli("run", tmp_path / "missing.mp4", "--out", tmp_path / "mine")
    assert proc.returncode == 2 and (tmp_path / "mine").is_dir()


def test_the_progress_bar_and_the_summary_give_one_fps(tmp_path):
    seen = []
    with open_source("sim:room", seconds=1.0, width=64, height=48) as src:
        summary = run_source(src, tmp_path, RunConfig(normals="source"), on_result=lambda r, stats: seen.append(
            (stats.estimates, stats.fps)))
    assert seen[-1][0] == summary["estimates"] == 30
    assert summary["fps"] == pytest.approx(summary["estimates"] / summary["wall_s"])
    assert seen[-1][1] == pytest.approx(summary["fps"], rel=0.2)  # the bar's last value: only closing the files after


def test_horizon_says_where_its_estimates_went(tmp_path):
    proc = cli("horizon", "sim:room", "--normals", "source", "--max-frames", 3, "--out", tmp_path / "clip.mp4")
    assert proc.returncode == 0, proc.stderr
    assert (f"the estimates (trajectory.tum, estimates.csv, summary.json) are in {tmp_path / 'clip.run'}/"
            in " ".join(proc.stdout.split()))
    assert (tmp_path / "clip.run" / "summary.json").is_file()


def test_the_demo_writes_to_a_named_temporary_folder_and_says_so(tmp_path, monkeypatch):
    used = {}
    monkeypatch.setattr(demo_module, "solver_demo", lambda console: {})
    monkeypatch.setattr(demo_module, "fusion_demo", lambda console, out_dir, **kw: used.setdefault("out", out_dir))
    proc = cli("demo", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert used["out"] == demo_module.default_out_dir() and not str(used["out"]).startswith(str(tmp_path))
    assert f"The demo writes its plot and video to {demo_module.default_out_dir()}" in proc.stdout
    assert list(tmp_path.iterdir()) == []


def test_the_demo_notes_the_first_solve_load_apart():
    out = io.StringIO()
    figures = demo_module.solver_demo(Console(file=out, width=200))
    assert figures["warm_up_ms"] > 0
    text = out.getvalue()
    assert f"after a first warm-up solve that loaded the compiled kernels ({figures['warm_up_ms']:.0f} ms" in text
