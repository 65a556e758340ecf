"""`uareme-fusion run SOURCE --out DIR` and `uareme-fusion eval SOURCE --out DIR`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from ..config import load_config, preset_names, validate_config
from ..pipeline import RunConfig
from ..pipeline.session import open_for_run, output_folder, run_notes, run_source
from .app import StdoutConsole, app, err_console, fail
from .progress import frame_progress

SOURCE_HELP = ("A video file, webcam:N, an image, folder or glob of images, a dataset folder (TUM RGB-D, "
               "ICL-NUIM, EuRoC, one written by 'simulate'), a ROS bag (.bag, a ROS 2 bag folder, .mcap), a BROAD "
               ".hdf5 or IMU .csv, sim:SCENARIO, or oak[:ID].")
EKF_PRESETS = [name for name in preset_names() if name != "paper"]
"""The EKF presets shipped in configs/ (paper.yaml holds the smoother's settings)."""
STOP_EXIT_CODES = {"end": 0, "max_frames": 0, "source_error": 1, "input_error": 2, "interrupted": 130,
                   "output_error": 1}


def run_config(config: Optional[Path], **overrides) -> RunConfig:
    """The run configuration: the YAML file when given, then every option the user set on the command line."""
    cfg = load_config(config, RunConfig) if config is not None else RunConfig()
    given = {k: v for k, v in overrides.items() if v is not None}
    return validate_config({**cfg.model_dump(), **given}, RunConfig, "command-line options") if given else cfg


def execute(source: str, out: Path, cfg: RunConfig, imu: Optional[Path], fps: Optional[float], evaluate: bool,
            command: str, extra_sinks_factory=None, record_dir: Optional[Path] = None,
            gt: Optional[Path] = None, gt_time_offset_s: Optional[float] = None, force: bool = False,
            topics: Optional[dict] = None) -> dict:
    """Open the source, run it with a progress bar, report how it ended; exits non-zero when it failed.

    With `record_dir` the source's frames and IMU are also written there as they pass (our dataset
    layout: a live session replays exactly with `run RECORD_DIR`). `topics` chooses a ROS bag's topics
    (`image_topic`, ... as `open_source` takes them; None values are left to the bag)."""
    from ..drivers import record

    with output_folder(out, force) as out_dir:  # removed again when the run fails before writing into it
        opened = open_for_run(source, cfg, imu, fps, gt, gt_time_offset_s, topics)
        with (opened if record_dir is None else record(opened, record_dir)) as src:
            print_notes(*run_notes(src, cfg))
            sinks = extra_sinks_factory(src, out_dir, cfg) if extra_sinks_factory else []
            total = src.info.n_frames if src.info.has_frames else getattr(src, "n_batches", None)
            if cfg.max_frames and total:
                total = min(total, cfg.max_frames)
            with frame_progress(command, total) as on_result:
                summary = run_source(src, out_dir, cfg, evaluate=evaluate, extra_sinks=sinks, on_result=on_result,
                                     command=command)
    print_summary(summary)
    code = STOP_EXIT_CODES.get(summary["stopped"], 1)
    if summary["stopped"] == "interrupted":
        code = 128 + summary.get("signal", 2)
    if "summary_error" in summary:
        raise fail(f"{summary['error'] or 'the run ended'}; {summary['summary_error']}, so the outputs in "
                   f"{out_dir} have no summary.json", 1)
    if code:
        raise fail(f"{summary['error']} (outputs so far kept in {out_dir})", code)
    return summary


def print_notes(notes: list[str], fixes: list[str]) -> None:
    """The source's notes and automatic fixes, one line each on stderr (also in summary.json)."""
    for fix in fixes:
        err_console.print(f"warning: {fix}", markup=False, emoji=False, style="yellow")
    for note in notes:
        err_console.print(f"note: {note}", markup=False, emoji=False)


def viewer_sinks(rerun: Optional[Path], mcap: Optional[Path] = None, source: Optional[str] = None):
    """The sinks factory of `--rerun PATH` and `--mcap PATH` for `execute` (None without either); an
    `--mcap` that names the input `source` is refused."""
    if rerun is None and mcap is None:
        return None
    if mcap is not None:
        from ..io.safe_files import refuse_input_as_output

        refuse_input_as_output(mcap, [source])

    def factory(src, out_dir, cfg):
        sinks = []
        if rerun is not None:
            from ..sinks.rerun_file import RerunSink

            sinks.append(RerunSink(rerun, cfg.assumed_fov_deg))
        if mcap is not None:
            from ..sinks.mcap_file import McapSink

            sinks.append(McapSink(mcap, cfg.assumed_fov_deg))
        return sinks

    return factory


def bag_topics(image_topic=None, imu_topic=None, depth_topic=None, camera_info_topic=None, gt_topic=None) -> dict:
    """The ROS bag topic options as `open_source` takes them."""
    return dict(image_topic=image_topic, imu_topic=imu_topic, depth_topic=depth_topic,
                camera_info_topic=camera_info_topic, gt_topic=gt_topic)


def print_summary(summary: dict) -> None:
    console = StdoutConsole()
    table = Table(title=f"{summary['command']}: {summary['source']}", show_header=False)
    table.add_row("frames / estimates", f"{summary['frames']} / {summary['estimates']}")
    table.add_row("without visual rotation", str(summary["frames_without_visual"]))
    if summary.get("frames_without_depth"):
        table.add_row("without depth (flagged)", str(summary["frames_without_depth"]))
    if summary["source_info"].get("intrinsics_from"):
        table.add_row("intrinsics from", summary["source_info"]["intrinsics_from"])
    table.add_row("normals / backend", f"{summary['normals']} / {summary['backend']}")
    table.add_row("speed", f"{summary['fps']:.1f} fps ({summary['estimates']} estimates in {summary['wall_s']:.2f} s, "
                  f"warm-up {summary['warm_up_s']:.2f} s included)")
    table.add_row("ms per frame", ", ".join(f"{k} {v:.1f}" for k, v in summary["timing_ms"].items()))
    if summary["status_counts"]:
        table.add_row("status flags", ", ".join(f"{k} {v}" for k, v in summary["status_counts"].items()))
    if "are_deg" in summary and summary["are_deg"]:
        a, t = summary["are_deg"], summary["tilt_deg"]
        table.add_row("ARE deg (mean / median / max)", f"{a['mean']:.2f} / {a['median']:.2f} / {a['max']:.2f}")
        table.add_row("tilt deg (mean / p95 / max)" + (", after the constant alignment (the reference is not "
                      "gravity-aligned)" if "tilt_unaligned_deg" in summary else ""),
                      f"{t['mean']:.2f} / {t['p95']:.2f} / {t['max']:.2f}")
        if "tilt_unaligned_deg" in summary:
            u = summary["tilt_unaligned_deg"]
            table.add_row("tilt deg without alignment, against the reference's z (mean / p95 / max)",
                          f"{u['mean']:.2f} / {u['p95']:.2f} / {u['max']:.2f}")
        table.add_row("NEES mean", f"{summary['nees']['mean']:.2f}")
    est = summary.get("imu_rotation_estimate", {})
    if est.get("observable"):
        table.add_row("camera-IMU rotation (from data)",
                      f"{est['nearest_axis_letters']} within {est['nearest_axis_letters_deg']:.1f} deg; "
                      f"{est['angle_to_used_deg']:.1f} deg from the one used")
    if summary.get("video_frames_resized"):
        table.add_row("video frames resized", f"{summary['video_frames_resized']} of {summary['video_frames']} "
                      "(their size differs from the first frame's)")
    table.add_row("outputs", ", ".join(summary["outputs"]))
    console.print(table)
    if summary.get("normals_note"):
        err_console.print(f"note: {summary['normals_note']}", markup=False, emoji=False)
    for line in summary.get("warnings", []):
        err_console.print(f"[bold yellow]warning:[/] {line}", markup=True, emoji=False, highlight=False)


def _options():
    return dict(
        imu=typer.Option(None, "--imu", help="IMU CSV in EuRoC format (t ns, gyro rad/s, accel m/s^2) merged by time."),
        backend=typer.Option(None, "--backend", help="mekf (default), smoother or single."),
        normals=typer.Option(None, "--normals",
                             help="auto (default), learned, depth, source, a model file (.pt, .onnx) or a folder "
                                  "of normal maps."),
        config=typer.Option(None, "--config", help="YAML run configuration (keys of RunConfig)."),
        preset=typer.Option(None, "--preset", help=f"EKF preset: {', '.join(EKF_PRESETS)} or a YAML path "
                                                    "(default: handheld with a camera, imu_only for an IMU log)."),
        intrinsics=typer.Option(None, "--intrinsics", help="Camera intrinsics: fx,fy,cx,cy in pixels (optionally "
                                "followed by k1,k2,p1,p2[,k3]) or a camera file (OpenCV YAML/JSON, Kalibr camchain, "
                                "EuRoC sensor.yaml); frames are undistorted."),
        max_frames=typer.Option(None, "--max-frames", help="Stop after this many frames."),
        fps=typer.Option(None, "--fps", help="Frame rate of an image folder without timestamps (default 30)."),
        offline=typer.Option(None, "--offline", help="A recorded IMU-only file: smooth it forward and backward "
                             "(more accurate than the streaming filter)."),
        cues=typer.Option(None, "--cues", help="Visual cues: normals, lines, sky (comma-separated; default all three)."),
        record=typer.Option(None, "--record", help="Also write the source's frames and IMU to this folder "
                                                     "(replay it later with 'run FOLDER')."),
        threads=typer.Option(None, "--threads", min=1, max=256,
                             help="torch CPU threads of the learned normals (default 1: fast beside other busy "
                                  "programs)."),
        imu_rotation=typer.Option(None, "--imu-rotation",
                                  help="Camera-from-IMU rotation: android, ios, axis letters of the IMU seen from "
                                       "the camera (rub, flu, ...), a 3x3 (9 numbers), a quaternion x,y,z,w or a "
                                       "Kalibr camchain .yaml (default: the source's own, identity)."),
        rerun=typer.Option(None, "--rerun", help="Also log the run to this rerun recording (.rrd): image with "
                                                   "horizon and axes, camera in 3D, tilt, std and status over "
                                                   "time, normals and confidence (needs the 'viewer' extra)."),
        imu_time_offset_s=typer.Option(None, "--imu-time-offset-s",
                                       help="Seconds added to IMU stamps to put them on the camera clock "
                                            "(default: the source's own, 0)."),
        force=typer.Option(False, "--force", help="Replace the results of an earlier run in a non-empty --out."),
        image_topic=typer.Option(None, "--image-topic", help="ROS bag: the sensor_msgs/Image or CompressedImage "
                                 "topic (default: the only one)."),
        imu_topic=typer.Option(None, "--imu-topic", help="ROS bag: the sensor_msgs/Imu topic (default: the only one)."),
        depth_topic=typer.Option(None, "--depth-topic", help="ROS bag: the depth topic, 16UC1 mm or 32FC1 m "
                                 "(default: the only one)."),
        camera_info_topic=typer.Option(None, "--camera-info-topic", help="ROS bag: the sensor_msgs/CameraInfo topic "
                                       "(default: the only one, or the image topic's)."),
        gt_topic=typer.Option(None, "--gt-topic", help="ROS bag: the ground-truth PoseStamped, "
                              "PoseWithCovarianceStamped or Odometry topic (default: the only one)."),
        mcap=typer.Option(None, "--mcap", help="Also write the run as an MCAP file for Foxglove: frames, camera "
                          "attitude (/tf), horizon and up annotations, covariance and status (needs the 'ros' extra)."),
    )


_o = _options()


@app.command("run")
def run_command(
    source: str = typer.Argument(..., help=SOURCE_HELP),
    out: Path = typer.Option(..., "--out", help="Folder for trajectory.tum, estimates.csv and summary.json."),
    imu: Optional[Path] = _o["imu"], backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"],
    threads: Optional[int] = _o["threads"], imu_rotation: Optional[str] = _o["imu_rotation"],
    imu_time_offset_s: Optional[float] = _o["imu_time_offset_s"],
    record: Optional[Path] = _o["record"], rerun: Optional[Path] = _o["rerun"], force: bool = _o["force"],
    intrinsics: Optional[str] = _o["intrinsics"], offline: Optional[bool] = _o["offline"],
    cues: Optional[str] = _o["cues"], mcap: Optional[Path] = _o["mcap"],
    image_topic: Optional[str] = _o["image_topic"], imu_topic: Optional[str] = _o["imu_topic"],
    depth_topic: Optional[str] = _o["depth_topic"], camera_info_topic: Optional[str] = _o["camera_info_topic"],
) -> None:
    """Estimate the camera orientation over a source; write trajectory.tum, estimates.csv, summary.json."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames,
                     intrinsics=intrinsics, threads=threads, imu_rotation=imu_rotation,
                     imu_time_offset_s=imu_time_offset_s, offline=offline, cues=cues)
    execute(source, out, cfg, imu, fps, evaluate=False, command="run", record_dir=record,
            extra_sinks_factory=viewer_sinks(rerun, mcap, source), force=force,
            topics=bag_topics(image_topic, imu_topic, depth_topic, camera_info_topic))


@app.command("eval")
def eval_command(
    source: str = typer.Argument(..., help="A source with ground truth (dataset folder, sim:SCENARIO, BROAD)."),
    out: Path = typer.Option(..., "--out", help="Folder for the outputs of 'run' plus the scores in summary.json."),
    imu: Optional[Path] = _o["imu"], backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"], force: bool = _o["force"],
    threads: Optional[int] = _o["threads"], imu_rotation: Optional[str] = _o["imu_rotation"],
    imu_time_offset_s: Optional[float] = _o["imu_time_offset_s"], rerun: Optional[Path] = _o["rerun"],
    intrinsics: Optional[str] = _o["intrinsics"], offline: Optional[bool] = _o["offline"],
    cues: Optional[str] = _o["cues"],
    gt: Optional[Path] = typer.Option(None, "--gt", help="Ground-truth trajectory (TUM 'timestamp tx ty tz qx qy qz "
                                                         "qw', or EuRoC gt0/data.csv) in place of the source's own."),
    gt_time_offset_s: Optional[float] = typer.Option(
        None, "--gt-time-offset-s", help="Seconds added to the ground truth's stamps to put them on the source's "
                                         "clock: of --gt (default 0), else of the source's own (default: TUM RGB-D "
                                         "+0.027, others 0)."),
    mcap: Optional[Path] = _o["mcap"],
    image_topic: Optional[str] = _o["image_topic"], imu_topic: Optional[str] = _o["imu_topic"],
    depth_topic: Optional[str] = _o["depth_topic"], camera_info_topic: Optional[str] = _o["camera_info_topic"],
    gt_topic: Optional[str] = _o["gt_topic"],
) -> None:
    """As 'run', then score against the source's ground truth: ARE, tilt, NEES, per-stage ms, fps."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames,
                     intrinsics=intrinsics, threads=threads, imu_rotation=imu_rotation,
                     imu_time_offset_s=imu_time_offset_s, offline=offline, cues=cues)
    execute(source, out, cfg, imu, fps, evaluate=True, command="eval",
            extra_sinks_factory=viewer_sinks(rerun, mcap, source),
            gt=gt, gt_time_offset_s=gt_time_offset_s, force=force,
            topics=bag_topics(image_topic, imu_topic, depth_topic, camera_info_topic, gt_topic))
