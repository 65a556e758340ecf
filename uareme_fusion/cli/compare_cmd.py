"""`uareme-fusion compare SOURCE --out DIR`: single, smoother (paper, gyro-aided) and mekf side by side."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import typer

from ..evaluation.compare import compare
from ..evaluation.sequence import synthetic_sequence
from ..evaluation.source_sequence import load_sequence
from .app import app, fail
from .run_cmd import _o, bag_topics, run_config

MAX_SYNTHETIC_DURATION_S = 3600.0
"""The synthetic sequence is held in memory: an hour at 15 fps is about 54000 frames."""


@app.command("compare")
def compare_command(
    source: Optional[str] = typer.Argument(None, help="Any source 'run' accepts (a video, images, a dataset "
                                                      "folder, sim:SCENARIO); a 'simulate' folder uses its "
                                                      "normals unless --normals or --cues is given."),
    out: Path = typer.Option(..., "--out", help="Folder for compare.md, compare.json and compare.png."),
    synthetic: Optional[str] = typer.Option(
        None, help="Build the sequence in memory from this simulator trajectory (walk, shake, static, bus, ...)."),
    seed: int = typer.Option(0, min=0, help="Seed of the synthetic sequence."),
    duration_s: float = typer.Option(20.0, "--duration-s", min=0.1, max=MAX_SYNTHETIC_DURATION_S,
                                     help="Length of the synthetic sequence, seconds."),
    drop_fraction: float = typer.Option(0.1, help="Synthetic: fraction of frames without a visual rotation."),
    bad_fraction: float = typer.Option(0.05, help="Synthetic: fraction of frames with random normals."),
    normals: Optional[str] = typer.Option(None, "--normals", help="As 'run': auto, learned, depth, source, a model "
                                                                  "file (.pt) or a folder of normal maps."),
    cues: Optional[str] = _o["cues"],
    imu: Optional[Path] = _o["imu"], max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"],
    threads: Optional[int] = _o["threads"], imu_rotation: Optional[str] = _o["imu_rotation"],
    imu_time_offset_s: Optional[float] = _o["imu_time_offset_s"],
    image_topic: Optional[str] = _o["image_topic"], imu_topic: Optional[str] = _o["imu_topic"],
    depth_topic: Optional[str] = _o["depth_topic"], camera_info_topic: Optional[str] = _o["camera_info_topic"],
    gt_topic: Optional[str] = _o["gt_topic"],
) -> None:
    """Run every backend on the same visual rotations and IMU; write a table and an error plot."""
    if (source is None) == (synthetic is None):
        raise fail("give either a dataset folder SOURCE or --synthetic SCENARIO (not both)")
    from ..pipeline.session import make_output_folder

    make_output_folder(out)  # refused before the sequence is computed
    if synthetic is not None:
        seq = synthetic_sequence(synthetic, seed=seed, duration_s=duration_s, drop_fraction=drop_fraction,
                                 bad_fraction=bad_fraction)
    elif normals is None and cues is None and imu is None and _has_saved_normals(Path(source)):
        seq = load_sequence(source)
    else:
        seq = _source_sequence(source, imu, fps, run_config(None, normals=normals, cues=cues, max_frames=max_frames,
                                                            threads=threads, imu_rotation=imu_rotation,
                                                            imu_time_offset_s=imu_time_offset_s),
                               bag_topics(image_topic, imu_topic, depth_topic, camera_info_topic, gt_topic))
    doc = compare(seq, out)
    typer.echo((out / "compare.md").read_text())
    typer.echo(f"wrote {out / 'compare.md'}, {out / 'compare.json'}, {out / 'compare.png'} "
               f"({len(doc['backends'])} backends)")


def _has_saved_normals(folder: Path) -> bool:
    """A folder written by 'simulate' (normals.npz or normals/): `load_sequence` reads it."""
    return folder.is_dir() and ((folder / "normals.npz").is_file() or (folder / "normals").is_dir())


def _source_sequence(spec: str, imu: Optional[Path], fps: Optional[float], cfg, topics: Optional[dict] = None):
    """The visual rotations of any source, computed once (`evaluation.source_sequence`)."""
    from ..evaluation.source_sequence import source_sequence
    from ..drivers import open_source
    from ..pipeline.session import configure_imu
    from ..pipeline.runner import RunStats
    from .progress import frame_progress

    with configure_imu(open_source(spec, imu=None if imu is None else str(imu), fps=fps, **(topics or {})),
                       cfg) as src:
        total = min(filter(None, [src.info.n_frames, cfg.max_frames]), default=None)
        with frame_progress("compare: visual rotations", total) as on_result:
            stats = RunStats(started_s=time.perf_counter())  # frame_progress reads its estimates and fps

            def progress(done, _):
                stats.estimates = done
                on_result(None, stats)

            return source_sequence(src, cfg, progress=progress)
