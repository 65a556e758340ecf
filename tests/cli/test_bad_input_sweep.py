"""The whole-CLI sweep of issue 15: every command given a missing file, a folder for a file, an empty
file (an empty --config is all defaults, by design: tests/core/test_config.py), an unreadable folder
(chmod 000; skipped as root) and an output on a read-only file system (a tmpfs mounted read-only;
skipped where it cannot be mounted). Each gives one error line naming the path, exit 2 for the
user's mistake or 1 for a failing environment, and no traceback."""

from __future__ import annotations

import os
import re

import pytest

from helpers import cli, error_lines, tmpfs

SOURCE_COMMANDS = ("run", "eval", "ground", "compare", "horizon")


def out_for(command: str, folder) -> str:
    return f"{folder}/o.mp4" if command == "horizon" else f"{folder}/o"


@pytest.fixture
def paths(tmp_path):
    (tmp_path / "folder").mkdir()
    for name in ("empty.mp4", "empty.csv", "empty.png", "empty.yaml", "empty.npz"):
        (tmp_path / name).write_bytes(b"")
    return tmp_path


def assert_nothing_written(folder) -> None:
    """No output file (an empty --out folder made before the input was opened may stay)."""
    assert not (folder / "o.mp4").exists() and not (folder / "o").is_file()
    assert not (folder / "o").is_dir() or not any((folder / "o").iterdir())


def assert_one_line(proc, code: int, pattern: str) -> None:
    lines = error_lines(proc)  # also: no traceback
    assert proc.returncode == code and len(lines) == 1 and re.search(pattern, lines[0]), (proc.returncode, lines)


@pytest.mark.parametrize("command", SOURCE_COMMANDS)
@pytest.mark.parametrize("kind, name, pattern", [
    ("missing", "nothing.mp4", r"nothing.mp4: no such file or folder \(expected a video"),
    ("folder", "folder", r"folder .*folder: not a dataset \(no rgb.txt"),
    ("empty_video", "empty.mp4", r"empty.mp4: empty file \(0 bytes\), expected a video, an image or an IMU table"),
    ("empty_table", "empty.csv", r"empty.csv: empty file \(0 bytes\)"),
    ("empty_image", "empty.png", r"empty.png: empty file \(0 bytes\)"),
])
def test_source_paths(paths, command, kind, name, pattern):
    assert_one_line(cli(command, paths / name, "--out", out_for(command, paths)), 2, pattern)
    assert_nothing_written(paths)


@pytest.mark.parametrize("args, pattern", [
    (["image", "P/nothing.png"], r"nothing.png: no such file"),
    (["image", "P/folder"], r"folder: no images"),
    (["image", "P/empty.png"], r"empty.png: empty file \(0 bytes\)"),
    (["normals", "P/nothing.png", "--out", "P/o"], r"nothing.png: no such file"),
    (["normals", "P/folder", "--out", "P/o"], r"folder: no images"),
    (["normals", "P/empty.png", "--out", "P/o"], r"empty.png: empty file \(0 bytes\)"),
    (["solve", "P/nothing.npz"], r"nothing.npz: no such file"),
    (["solve", "P/folder"], r"folder: is a folder, expected a normal-map file"),
    (["solve", "P/empty.npz"], r"empty.npz: not a readable .npz archive"),
    (["run", "sim:room", "--out", "P/o", "--imu", "P/nothing.csv"], r"nothing.csv does not exist"),
    (["run", "sim:room", "--out", "P/o", "--imu", "P/folder"], r"folder: is a folder, and an IMU file inside it"),
    (["run", "sim:room", "--out", "P/o", "--imu", "P/empty.csv"], r"empty.csv holds no IMU samples"),
    (["run", "sim:room", "--out", "P/o", "--config", "P/nothing.yaml"], r"nothing.yaml: No such file"),
    (["run", "sim:room", "--out", "P/o", "--config", "P/folder"], r"folder: it is a folder"),
    (["run", "sim:room", "--out", "P/o", "--normals", "P/nothing.pt"], r"nothing.pt: model file not found"),
    (["run", "sim:room", "--out", "P/o", "--normals", "P/folder"], r"folder: no normal maps"),
    (["run", "sim:room", "--out", "P/o", "--intrinsics", "P/nothing.yaml"], r"nothing.yaml'?: expected fx,fy,cx,cy"),
    (["run", "sim:room", "--out", "P/o", "--intrinsics", "P/folder"], r"camera file .*folder: is a folder"),
    (["run", "sim:room", "--out", "P/o", "--record", "P/empty.csv"], r"--record .*empty.csv: exists and is not a folder"),
    (["run", "sim:room", "--out", "P/o", "--rerun", "P/folder"], r"--rerun .*folder: a rerun recording is a .rrd file"),
    (["run", "sim:room", "--out", "P/empty.csv"], r"empty.csv: exists and is not a folder"),
    (["compare", "sim:room", "--max-frames", "2", "--out", "P/empty.csv"], r"empty.csv: exists and is not a folder"),
    (["simulate", "room", "--frames", "2", "--out", "P/empty.csv"], r"empty.csv exists and is not a folder"),
    (["bench", "solver", "--repeats", "5", "--json", "P/folder"], r"--json .*folder: cannot write a file there"),
    (["bench", "broad", "--data", "P/nothing"], r"--data .*nothing: holds no BROAD .hdf5 trials"),
])
def test_file_options(paths, args, pattern):
    proc = cli(*[a.replace("P/", f"{paths}/") for a in args])
    assert_one_line(proc, 2, pattern)
    assert_nothing_written(paths)


@pytest.fixture
def read_only(tmp_path):
    """A read-only tmpfs (needs root and mount); skips where the machine does not allow one."""
    with tmpfs(tmp_path / "ro", "ro,size=64k") as mount:
        yield mount


@pytest.mark.parametrize("args, pattern", [
    (["run", "sim:room", "--max-frames", "2", "--out", "RO/o"], r"RO/o: cannot create the output folder"),
    (["eval", "sim:room", "--max-frames", "2", "--out", "RO/o"], r"RO/o: cannot create the output folder"),
    (["ground", "sim:room", "--max-frames", "2", "--out", "RO/o"], r"RO/o: cannot create the output folder"),
    (["compare", "sim:room", "--max-frames", "2", "--out", "RO/o"], r"RO/o: cannot create the output folder"),
    (["horizon", "sim:room", "--max-frames", "2", "--out", "RO/o.mp4"], r"RO/o.run: cannot create the output folder"),
    (["normals", "IMG", "--out", "RO/o"], r"RO/o: cannot create the output folder"),
    (["image", "IMG", "--cues", "lines", "--out", "RO/o.png"], r"RO/o.png: could not be written"),
    (["simulate", "room", "--frames", "2", "--size", "80x60", "--out", "RO/o"], r"RO/o"),
    (["run", "sim:room", "--max-frames", "2", "--out", "T/o", "--record", "RO/o"], r"RO/o/rgb: could not be written"),
    (["run", "sim:room", "--max-frames", "2", "--out", "T/o", "--rerun", "RO/o.rrd"], r"RO/o.rrd: could not be written"),
    (["bench", "solver", "--repeats", "5", "--json", "RO/o.json"], r"RO/o.json: could not be written"),
])
def test_outputs_on_a_read_only_file_system_exit_1(read_only, tmp_path, args, pattern):
    if "--rerun" in args:
        pytest.importorskip("rerun")
    if "IMG" in args:
        assert cli("simulate", "room", "--frames", "1", "--size", "160x120", "--out", tmp_path / "s").returncode == 0
        image = next((tmp_path / "s" / "rgb").iterdir())
    else:
        image = None
    args = [str(image) if a == "IMG" else a.replace("RO/", f"{read_only}/").replace("T/", f"{tmp_path}/") for a in args]
    proc = cli(*args)
    assert_one_line(proc, 1, pattern.replace("RO/", re.escape(f"{read_only}/")) + r".*Read-only file system")
    assert os.listdir(read_only) == []


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root reads and writes past chmod 000")
@pytest.mark.parametrize("command", ["run", "normals", "image"])
def test_an_unreadable_folder(tmp_path, command):
    locked = tmp_path / "locked"
    locked.mkdir()
    (locked / "a.png").write_bytes(b"x")
    locked.chmod(0)
    try:
        args = [command, locked / "a.png"] + ([] if command == "image" else ["--out", tmp_path / "o"])
        proc = cli(*args)
        assert proc.returncode == 2 and len(error_lines(proc)) == 1 and "a.png" in error_lines(proc)[0]
    finally:
        locked.chmod(0o755)
