"""Nothing lost, nothing overwritten (issue 15), through the real command line: an output that is the
input, a non-empty --out, links planted in --out, clashing names, SIGTERM/SIGHUP/Ctrl-C, a full disk
(a small tmpfs, where this machine lets us mount one), a closed stdout, frames of mixed sizes.
Each test checks the message, the exit status and that the files written before it are complete."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from uareme_fusion.errors import InputError, OutputError
from uareme_fusion.io.safe_files import RowFile, write_npz_atomic
from helpers import assert_outputs_complete, cli, error_lines, subprocess_env, tmpfs

def write_video(path: Path, frames: int = 12, size=(64, 48)) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, size)
    rng = np.random.default_rng(0)
    for _ in range(frames):
        writer.write(rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8))
    writer.release()
    return path


def video_frames(path: Path) -> int:
    capture = cv2.VideoCapture(str(path))
    count = 0
    while capture.read()[0]:
        count += 1
    capture.release()
    return count


# ------------------------------------------------------------------------------ overwrites
def test_horizon_refuses_to_write_over_its_input(tmp_path):
    video = write_video(tmp_path / "in.mp4")
    before = video.read_bytes()
    for out in ("in.mp4", str(video)):  # the same file, spelled two ways
        proc = cli("horizon", "in.mp4", "--out", out, "--force", cwd=tmp_path)
        assert proc.returncode == 2
        assert error_lines(proc) == [f"error: --out {out} is the input in.mp4; writing it would destroy the input "
                                     "(choose another output name)"]
    assert video.read_bytes() == before


@pytest.mark.slow
@pytest.mark.parametrize("command", ["run", "eval", "ground"])
def test_a_non_empty_out_needs_force(tmp_path, command):
    out = tmp_path / "out"
    args = [command, "sim:room", "--max-frames", "3", "--out", out]
    assert cli(*args).returncode == 0
    first = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    proc = cli(*args)
    assert proc.returncode == 2
    assert error_lines(proc)[0].startswith(f"error: --out {out} is not empty (holds ")
    assert error_lines(proc)[0].endswith("pass --force to replace the results in it")
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == first  # untouched
    assert cli(*args, "--force").returncode == 0
    assert_outputs_complete(out, 3, "max_frames")


def test_a_link_planted_in_out_is_never_written_through(tmp_path):
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "trajectory.tum").symlink_to(victim)
    proc = cli("run", "sim:room", "--max-frames", "3", "--out", out)
    assert proc.returncode == 2 and "is not empty" in error_lines(proc)[0]
    proc = cli("run", "sim:room", "--max-frames", "3", "--out", out, "--force")
    assert proc.returncode == 0, proc.stderr
    assert victim.read_text() == "keep me\n" and not (out / "trajectory.tum").is_symlink()
    assert_outputs_complete(out, 3, "max_frames")


def test_row_files_and_atomic_files_refuse_links(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("x")
    (tmp_path / "link.tum").symlink_to(victim)
    with pytest.raises(InputError, match=r"link.tum: is a symbolic link \(to .*victim\); refusing to write"):
        RowFile(tmp_path / "link.tum")
    (tmp_path / "link.npz").symlink_to(victim)
    with pytest.raises(InputError, match="is a symbolic link"):
        write_npz_atomic(tmp_path / "link.npz", a=np.zeros(3))
    assert victim.read_text() == "x"


@pytest.mark.slow
def test_normals_of_images_sharing_a_stem_get_distinct_names(tmp_path):
    folder = tmp_path / "images"
    folder.mkdir()
    rng = np.random.default_rng(0)
    cv2.imwrite(str(folder / "a.png"), rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
    cv2.imwrite(str(folder / "a.jpg"), rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
    proc = cli("normals", folder, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    assert "wrote 2 frame(s)" in proc.stdout
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == ["a_jpg.npz", "a_jpg_confidence.png", "a_jpg_normals.png",
                     "a_png.npz", "a_png_confidence.png", "a_png_normals.png"]
    maps = [np.load(tmp_path / "out" / n) for n in ("a_jpg.npz", "a_png.npz")]
    assert not np.array_equal(maps[0]["normals"], maps[1]["normals"])  # two images, two maps
    proc = cli("normals", folder, "--out", tmp_path / "out")
    assert proc.returncode == 2 and "pass --force" in error_lines(proc)[0]


def test_an_interrupted_atomic_write_leaves_no_file(tmp_path, monkeypatch):
    """Ctrl-C while an .npz is written (here: inside the write) leaves neither a truncated file under the
    final name nor a temporary one; a file of that name written before stays as it was."""
    path = tmp_path / "a.npz"
    write_npz_atomic(path, normals=np.ones((2, 2, 3), np.float32))
    before = path.read_bytes()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_npz_atomic(path, normals=np.zeros((2, 2, 3), np.float32))
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.npz"]


# ------------------------------------------------------------------------------ signals
def start(args, out_file: Path, rows: int = 6) -> subprocess.Popen:
    """Start the CLI and wait until `out_file` holds `rows` lines."""
    proc = subprocess.Popen([sys.executable, "-m", "uareme_fusion", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=subprocess_env())
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if out_file.is_file() and out_file.read_text().count("\n") >= rows:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be stopped"
    return proc


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_stop_like_ctrl_c_with_a_playable_video(tmp_path, sig):
    out_video = tmp_path / "h.mp4"
    proc = start(["horizon", "sim:room", "--out", out_video], tmp_path / "h.run" / "trajectory.tum")
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, stderr
    assert "Traceback" not in stderr and f"stopped by {signal.Signals(sig).name}" in stderr
    summary = assert_outputs_complete(tmp_path / "h.run", json.loads((tmp_path / "h.run" / "summary.json")
                                                                     .read_text())["frames"], "interrupted")
    assert summary["signal"] == sig and 5 <= summary["estimates"] < 300
    assert video_frames(out_video) == summary["estimates"] == summary["video_frames"]  # index written


@pytest.mark.slow
def test_ctrl_c_in_ground_video_counts_what_the_files_hold(tmp_path):
    out = tmp_path / "g"
    proc = start(["ground", "sim:room", "--video", "--out", out], out / "trajectory.tum", rows=4)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert_outputs_complete(out, summary["frames"], "interrupted")
    assert len(list((out / "masks").iterdir())) == summary["ground_masks"] == summary["estimates"]
    assert video_frames(out / "ground.mp4") == summary["estimates"]


@pytest.mark.slow
def test_a_closed_stdout_after_a_completed_run_exits_0(tmp_path):
    proc = subprocess.run(["bash", "-c", f"{sys.executable} -m uareme_fusion run sim:room --max-frames 3 --out "
                           f"{tmp_path / 'out'} | head -c 0; exit ${{PIPESTATUS[0]}}"],
                          capture_output=True, text=True, env=subprocess_env(), timeout=120)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr and "error" not in proc.stderr
    assert_outputs_complete(tmp_path / "out", 3, "max_frames")


# ------------------------------------------------------------------------------ full disk
@pytest.fixture
def small_disk(tmp_path, request):
    """A 200 KiB tmpfs (needs root and mount) with a filler of `request.param` bytes (170,000 unless
    the test says: leaves about 30 KiB); skips where the machine does not allow one."""
    with tmpfs(tmp_path / "disk", "size=200k") as mount:
        (mount / "filler").write_bytes(bytes(getattr(request, "param", 170_000)))
        yield mount


def assert_rows_complete(out: Path) -> dict:
    """After a full disk: summary.json says output_error, and the tables hold exactly its estimates
    as whole rows (the frame being written when the disk filled is in neither)."""
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] == "output_error" and "No space left on device" in summary["error"]
    assert summary["frames"] - summary["estimates"] in (0, 1)
    n = summary["estimates"]
    rows = [ln.split() for ln in (out / "trajectory.tum").read_text().splitlines() if not ln.startswith("#")]
    assert len(rows) == n and all(len(r) == 8 for r in rows)
    csv_lines = (out / "estimates.csv").read_text().splitlines()
    assert len(csv_lines) == n + 1 and all(ln.count(",") == csv_lines[0].count(",") for ln in csv_lines)
    return summary


@pytest.mark.slow
def test_a_full_disk_keeps_every_complete_row_and_exits_1(small_disk):
    out = small_disk / "out"
    proc = cli("run", "sim:room", "--out", out)
    assert proc.returncode == 1
    (line,) = error_lines(proc)
    assert "could not be written (No space left on device); kept its" in line and str(out) in line
    summary = assert_rows_complete(out)
    assert 20 < summary["estimates"] < 300


@pytest.mark.slow
@pytest.mark.parametrize("small_disk", [170_000, 180_000], indirect=True)  # 180,000: the disk fills as the
def test_a_full_disk_during_horizon_names_the_file_and_leaves_no_broken_video(small_disk):  # mp4 closes (segfaulted)
    proc = cli("horizon", "sim:room", "--max-frames", "100", "--out", small_disk / "h.mp4")
    assert proc.returncode == 1
    (line,) = error_lines(proc)
    assert f"error: {small_disk}/" in line and ": could not be written" in line
    summary = assert_rows_complete(small_disk / "h.run")
    if (small_disk / "h.mp4").exists():  # finished before the disk filled: every frame plays
        assert video_frames(small_disk / "h.mp4") == summary["estimates"]
    else:
        assert f"{small_disk / 'h.mp4'}: could not be written" in summary["error"]
    assert [p.name for p in small_disk.iterdir() if p.name.startswith(".")] == []  # no temporary left


def test_a_full_disk_during_simulate_names_the_file(small_disk):
    proc = cli("simulate", "room", "--frames", "60", "--size", "160x120", "--out", small_disk / "s")
    assert proc.returncode == 1
    (line,) = error_lines(proc)
    assert line.startswith(f"error: {small_disk / 's'}/") and line.endswith("could not be written (No space left "
                                                                             "on device)")
    for png in (small_disk / "s" / "rgb").iterdir():  # every image that is there decodes
        assert cv2.imread(str(png)) is not None


def test_row_file_truncates_a_partial_row(tmp_path, monkeypatch):
    rows = RowFile(tmp_path / "t.tum")
    rows.write_row("# header\n", counts=False)
    rows.write_row("1 2 3\n")
    real_write = os.write

    def half_then_full(fd, data):  # the disk takes 3 bytes, then is full
        monkeypatch.setattr(os, "write", lambda *a: (_ for _ in ()).throw(OSError(28, "No space left on device")))
        return real_write(fd, bytes(data[:3]))

    monkeypatch.setattr(os, "write", half_then_full)
    with pytest.raises(OutputError, match=r"t.tum: could not be written \(No space left on device\); kept its 1 "):
        rows.write_row("4 5 6\n")
    rows.close()
    assert (tmp_path / "t.tum").read_text() == "# header\n1 2 3\n"


# ------------------------------------------------------------------------------ mixed frame sizes
def test_overlay_videos_resize_frames_of_another_size_and_say_so(tmp_path):
    folder = tmp_path / "mixed"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(6):
        size = (150, 200) if i in (2, 4) else (48, 64)
        cv2.imwrite(str(folder / f"{i:03d}.png"), rng.integers(0, 256, (*size, 3), dtype=np.uint8))
    proc = cli("ground", folder, "--video", "--out", tmp_path / "g")
    assert proc.returncode == 0, proc.stderr
    assert "2 of 6 (their size differs from the first frame's)" in proc.stdout
    summary = json.loads((tmp_path / "g" / "summary.json").read_text())
    assert summary["video_frames"] == 6 and summary["video_frames_resized"] == 2
    assert video_frames(tmp_path / "g" / "ground.mp4") == 6


def test_a_full_disk_during_ground_keeps_masks_and_overlays_in_step(small_disk):
    out = small_disk / "g"
    proc = cli("ground", "sim:room", "--max-frames", "40", "--out", out)
    assert proc.returncode == 1
    (line,) = error_lines(proc)
    assert f"error: {out}/" in line and "could not be written (No space left on device)" in line
    summary = assert_rows_complete(out)
    masks, overlays = sorted((out / "masks").iterdir()), sorted((out / "overlay").iterdir())
    assert len(masks) == len(overlays) == summary["ground_masks"] == summary["estimates"]
    assert all(cv2.imread(str(p)) is not None for p in masks + overlays)


def test_a_full_disk_during_record_leaves_a_replayable_prefix(small_disk, tmp_path):
    (small_disk / "filler").unlink()  # 200 KiB: the IMU, the ground truth and about one frame fit
    rec = small_disk / "r"
    proc = cli("run", "sim:room", "--max-frames", "40", "--out", tmp_path / "out", "--record", rec)
    assert proc.returncode == 1
    (line,) = error_lines(proc)
    assert line.startswith(f"error: {rec}/") and "could not be written (No space left on device)" in line
    meta = json.loads((rec / "source.json").read_text())  # the counts of close, not the placeholder
    listed = [ln.split() for ln in (rec / "rgb.txt").read_text().splitlines()
              if not ln.startswith("#")] if (rec / "rgb.txt").exists() else []
    assert meta["frames"] == len(listed) and all(cv2.imread(str(rec / name)) is not None for _, name in listed)
    imu_rows = (rec / "imu0" / "data.csv").read_text().splitlines()[1:]
    assert meta["imu_samples"] == len(imu_rows) > 0 and all(row.count(",") == 6 for row in imu_rows)
    truth = [ln.split() for ln in (rec / "groundtruth.txt").read_text().splitlines() if not ln.startswith("#")]
    assert len(truth) == 300 and all(len(row) == 8 for row in truth)
    assert [p.name for p in rec.rglob(".*")] == []  # no temporary file left
    replay = cli("run", rec, "--out", tmp_path / "replay")
    assert replay.returncode == 0, replay.stderr
    assert json.loads((tmp_path / "replay" / "summary.json").read_text())["imu_samples"] == len(imu_rows)


def test_bench_json_is_written_whole(tmp_path, monkeypatch):
    """`bench --json FILE` goes through a temporary file: a failing write leaves the older file as it was."""
    from uareme_fusion.benchmarks import solver

    monkeypatch.setattr(solver, "run", lambda repeats: {"median_ms": 1.5})
    out = tmp_path / "b.json"
    assert cli("bench", "solver", "--repeats", "5", "--json", out).returncode == 0
    assert json.loads(out.read_text()) == {"median_ms": 1.5}
    monkeypatch.setattr(solver, "run", lambda repeats: {"median_ms": 2.5})
    monkeypatch.setattr(os, "fsync", lambda fd: (_ for _ in ()).throw(OSError(28, "No space left on device")))
    proc = cli("bench", "solver", "--repeats", "5", "--json", out)
    assert proc.returncode == 1
    assert error_lines(proc) == [f"error: {out}: could not be written (No space left on device)"]
    assert json.loads(out.read_text()) == {"median_ms": 1.5} and sorted(p.name for p in tmp_path.iterdir()) == ["b.json"]


def test_image_overlays_of_images_sharing_a_stem_get_distinct_names(tmp_path):
    """`image a.png a.jpg --out DIR` names the overlays as `normals` does; a non-empty DIR, an existing
    overlay file or two inputs with one name are refused, and nothing is overwritten without --force."""
    assert cli("simulate", "room", "--frames", "2", "--size", "160x120", "--out", tmp_path / "s").returncode == 0
    images = tmp_path / "images"
    images.mkdir()
    rgb = sorted((tmp_path / "s" / "rgb").iterdir())
    cv2.imwrite(str(images / "a.png"), cv2.imread(str(rgb[0])))
    cv2.imwrite(str(images / "a.jpg"), cv2.imread(str(rgb[1])))
    out = tmp_path / "o"
    proc = cli("image", images, "--cues", "lines", "--json", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert [Path(json.loads(ln)["image"]).name for ln in proc.stdout.splitlines()] == ["a.jpg", "a.png"]
    assert sorted(p.name for p in out.iterdir()) == ["a_jpg.png", "a_png.png"]
    written = {p.name: p.read_bytes() for p in out.iterdir()}
    assert written["a_jpg.png"] != written["a_png.png"]  # two images, two overlays
    assert all(cv2.imread(str(p)).shape == (120, 160, 3) for p in out.iterdir())
    proc = cli("image", images, "--cues", "lines", "--out", out)
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: --out {out} is not empty (holds a_jpg.png, a_png.png); "
                                 "pass --force to replace the results in it"]
    proc = cli("image", images / "a.png", "--cues", "lines", "--out", out / "a_png.png")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: --out {out / 'a_png.png'} exists; pass --force to replace it"]
    proc = cli("image", images / "a.png", images / "a.png", "--cues", "lines", "--out", tmp_path / "o2")
    assert proc.returncode == 2
    assert error_lines(proc) == [f"error: {images / 'a.png'}, {images / 'a.png'}: these images would write the "
                                 "same outputs (a_png); rename them"]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == written and not (tmp_path / "o2").exists()
    proc = cli("image", images, "--cues", "lines", "--out", out, "--force")
    assert proc.returncode == 0 and sorted(p.name for p in out.iterdir()) == ["a_jpg.png", "a_png.png"]
