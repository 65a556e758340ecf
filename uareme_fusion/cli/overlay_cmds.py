"""`uareme-fusion horizon VIDEO --out VIDEO` and `uareme-fusion ground INPUT --out DIR`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import InputError
from ..io.safe_files import refuse_input_as_output, refuse_link
from ..sinks.drawing import VIDEO_CODECS, GroundSink, HorizonVideoSink
from .app import app
from .run_cmd import _o, bag_topics, execute, run_config


def needs_frames(src, command: str) -> None:
    """`InputError` when the source has no images to draw on (an IMU log)."""
    if not src.info.has_frames:
        raise InputError(f"{src.info.name}: '{command}' draws on images, and this source has none (IMU only)")


@app.command("horizon")
def horizon_command(
    source: str = typer.Argument(..., help="A video (or any source 'run' accepts)."),
    out: Path = typer.Option(..., "--out", help="Overlay video (.mp4 or .avi); estimates go to OUT_STEM.run/."),
    imu: Optional[Path] = _o["imu"], backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"],
    intrinsics: Optional[str] = _o["intrinsics"],
    threads: Optional[int] = _o["threads"], imu_rotation: Optional[str] = _o["imu_rotation"],
    imu_time_offset_s: Optional[float] = _o["imu_time_offset_s"],
    cues: Optional[str] = _o["cues"],
    panes: bool = typer.Option(False, "--panes", help="Add panes of normals and confidence beside each frame."),
    fov_deg: Optional[float] = typer.Option(None, "--fov-deg",
                                            help="Assumed horizontal field of view when K is unknown (default 60)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out video and its OUT_STEM.run/ results."),
    image_topic: Optional[str] = _o["image_topic"], imu_topic: Optional[str] = _o["imu_topic"],
    depth_topic: Optional[str] = _o["depth_topic"], camera_info_topic: Optional[str] = _o["camera_info_topic"],
) -> None:
    """Draw the horizon and the Manhattan axes on every frame of a video."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames,
                     intrinsics=intrinsics, threads=threads, imu_rotation=imu_rotation,
                     imu_time_offset_s=imu_time_offset_s, assumed_fov_deg=fov_deg, cues=cues)
    if out.suffix.lower() not in VIDEO_CODECS:
        raise InputError(f"--out {out}: unsupported video extension; use one of {', '.join(VIDEO_CODECS)}")
    refuse_input_as_output(out, [source, imu])
    refuse_link(out)
    if out.exists() and not force:
        raise InputError(f"--out {out} exists; pass --force to replace it")

    def sinks(src, out_dir, cfg):
        needs_frames(src, "horizon")
        return [HorizonVideoSink(out, src.info.fps or 30.0, cfg.assumed_fov_deg, panes)]

    run_dir = out.parent / f"{out.stem}.run"
    summary = execute(source, run_dir, cfg, imu, fps, evaluate=False, command="horizon",
                      extra_sinks_factory=sinks, force=force,
                      topics=bag_topics(image_topic, imu_topic, depth_topic, camera_info_topic))
    typer.echo(f"wrote {out} ({summary.get('videos', {}).get(out.name, 'no frames')}); the estimates "
               f"(trajectory.tum, estimates.csv, summary.json) are in {run_dir}/")


@app.command("ground")
def ground_command(
    source: str = typer.Argument(..., help="An image, folder of images, video or dataset."),
    out: Path = typer.Option(..., "--out", help="Folder for masks/, overlay/ (or ground.mp4) and the estimates."),
    imu: Optional[Path] = _o["imu"], backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"],
    intrinsics: Optional[str] = _o["intrinsics"],
    threads: Optional[int] = _o["threads"], imu_rotation: Optional[str] = _o["imu_rotation"],
    imu_time_offset_s: Optional[float] = _o["imu_time_offset_s"],
    cues: Optional[str] = _o["cues"],
    video: bool = typer.Option(False, "--video", help="Write the overlays as OUT/ground.mp4 instead of images."),
    threshold_deg: Optional[float] = typer.Option(None, "--threshold-deg",
                                                  help="Ground when the normal is within this angle of up (15)."),
    force: bool = _o["force"],
    image_topic: Optional[str] = _o["image_topic"], imu_topic: Optional[str] = _o["imu_topic"],
    depth_topic: Optional[str] = _o["depth_topic"], camera_info_topic: Optional[str] = _o["camera_info_topic"],
) -> None:
    """Segment the ground: pixels whose normal is within a threshold of the estimated up vector."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames,
                     intrinsics=intrinsics, threads=threads, imu_rotation=imu_rotation,
                     imu_time_offset_s=imu_time_offset_s, ground_threshold_deg=threshold_deg, cues=cues)

    def sinks(src, out_dir, cfg):
        needs_frames(src, "ground")
        return [GroundSink(out_dir, cfg.ground_threshold_deg, out_dir / "ground.mp4" if video else None,
                           src.info.fps or 30.0)]

    execute(source, out, cfg, imu, fps, evaluate=False, command="ground", extra_sinks_factory=sinks, force=force,
            topics=bag_topics(image_topic, imu_topic, depth_topic, camera_info_topic))
