"""`uareme-fusion batch` (issue 28 item 3): four sources, one broken, on the process pool and on a real
local Ray cluster: 3 ok, 1 failed, exit 1, batch.csv one row each, every ok source's outputs those of
a plain `run` of it; `--resume` skips what ended; source lists and folder names."""

from __future__ import annotations

import csv
import importlib.util
import json

import pytest

from uareme_fusion.errors import InputError
from uareme_fusion.pipeline.batch import BATCH_COLUMNS, batch_names, read_source_list
from uareme_fusion.sim.dataset import SequenceOptions, write_sequence
from helpers import cli

TIMING_KEYS = ("fps", "wall_s", "warm_up_s", "timing_ms")
"""summary.json keys that measure this machine's speed, not the estimates."""


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Two small simulated recordings; the sources: both IMU logs, one camera folder, one broken table."""
    root = tmp_path_factory.mktemp("recordings")
    for seed in (0, 1):
        write_sequence("room", root / f"rec{seed}", SequenceOptions(frames=8, width=64, height=48, seed=seed))
    (root / "broken.csv").write_text("this is not an IMU table\n")
    (root / "list.txt").write_text(f"{root / 'rec0' / 'imu0' / 'data.csv'}\n# a comment\n\n"
                                   f"{root / 'rec1' / 'imu0' / 'data.csv'}\n")
    return root


def sources_of(root):
    return [f"@{root / 'list.txt'}", str(root / "rec0"), str(root / "broken.csv")]


def rows_of(out):
    with open(out / "batch.csv", newline="") as fh:
        return {row["source"]: row for row in csv.DictReader(fh)}


def without_timing(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k not in TIMING_KEYS}


def assert_three_ok_one_failed(proc, out, root):
    assert proc.returncode == 1, proc.stderr
    rows = rows_of(out)
    assert list(next(csv.reader(open(out / "batch.csv")))) == list(BATCH_COLUMNS)
    imu0, imu1 = str(root / "rec0" / "imu0" / "data.csv"), str(root / "rec1" / "imu0" / "data.csv")
    assert sorted(rows) == sorted([imu0, imu1, str(root / "rec0"), str(root / "broken.csv")])
    assert [rows[s]["status"] for s in (imu0, imu1, str(root / "rec0"))] == ["ok"] * 3
    broken = rows[str(root / "broken.csv")]
    assert broken["status"] == "failed" and "broken.csv is not an EuRoC IMU file" in broken["error"]
    assert rows[str(root / "rec0")]["frames"] == "8" and float(rows[imu0]["fps"]) > 0
    assert "3 ok, 1 failed" in proc.stdout
    return {imu0: out / "rec0_imu0_data", imu1: out / "rec1_imu0_data", str(root / "rec0"): out / "rec0"}


def assert_same_as_plain_runs(folders, tmp_path):
    for i, (source, folder) in enumerate(folders.items()):
        plain = tmp_path / f"plain{i}"
        assert cli("run", source, "--out", plain).returncode == 0
        for name in ("trajectory.tum", "estimates.csv"):
            assert (folder / name).read_bytes() == (plain / name).read_bytes(), (source, name)
        ours, theirs = (json.loads((f / "summary.json").read_text()) for f in (folder, plain))
        assert without_timing(ours) == without_timing(theirs)


@pytest.mark.slow
def test_batch_on_the_process_pool(recordings, tmp_path):
    out = tmp_path / "batch"
    proc = cli("batch", *sources_of(recordings), "--out", out, "--workers", 2)
    folders = assert_three_ok_one_failed(proc, out, recordings)
    assert_same_as_plain_runs(folders, tmp_path)
    assert not (out / "broken").exists()  # a source that did not open leaves no folder
    # --resume: the three that ended are kept as they are, the broken one is tried again
    stamps = {s: (f / "summary.json").stat().st_mtime_ns for s, f in folders.items()}
    proc = cli("batch", *sources_of(recordings), "--out", out, "--workers", 2, "--resume")
    assert proc.returncode == 1
    assert {s: (f / "summary.json").stat().st_mtime_ns for s, f in folders.items()} == stamps
    assert [r["status"] for r in rows_of(out).values()].count("ok") == 3
    # without --resume or --force, earlier results are not replaced: each source says so
    proc = cli("batch", str(recordings / "rec0"), "--out", out)
    assert proc.returncode == 1 and "pass --force" in rows_of(out)[str(recordings / "rec0")]["error"]


@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="ray is not installed (the ray extra)")
@pytest.mark.slow
def test_batch_on_a_local_ray_cluster(recordings, tmp_path):
    out = tmp_path / "batch_ray"
    proc = cli("batch", *sources_of(recordings), "--out", out, "--workers", 2, "--ray", "local")
    folders = assert_three_ok_one_failed(proc, out, recordings)
    assert_same_as_plain_runs(folders, tmp_path)


def test_source_lists_and_folder_names(tmp_path):
    (tmp_path / "list.txt").write_text("a.bag\n\n# skipped\n  sim:room  \n")
    assert read_source_list([f"@{tmp_path / 'list.txt'}", "b.csv"]) == ["a.bag", "sim:room", "b.csv"]
    with pytest.raises(InputError, match="missing.txt: cannot read the list of sources"):
        read_source_list([f"@{tmp_path / 'missing.txt'}"])
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(InputError, match="no sources given"):
        read_source_list([f"@{tmp_path / 'empty.txt'}"])
    for name in ("V1_02/mav0/imu0", "V1_01/mav0/imu0"):
        (tmp_path / name).mkdir(parents=True)
        (tmp_path / name / "data.csv").write_text("")
    assert batch_names([str(tmp_path / "V1_02/mav0/imu0/data.csv"), str(tmp_path / "V1_01/mav0/imu0/data.csv"),
                        "sim:room", "sim:room", str(tmp_path / "V1_02")]) == [
        "V1_02_mav0_imu0_data", "V1_01_mav0_imu0_data", "sim_room", "sim_room_2", "V1_02"]
