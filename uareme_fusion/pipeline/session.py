"""One run from a source to an output folder: `trajectory.tum`, `estimates.csv`, `summary.json`.

`summary.json` is written however the run ends (end of source, `max_frames`, a source failure,
bad input met mid-stream, Ctrl-C, SIGTERM, a full disk), with `stopped` saying which; the trajectory and CSV are
written row by row. Its disk space is reserved when the run starts (until the end it says
`"stopped": "running"`), so a disk that fills during the run does not keep it out. With
`evaluate=True` the source's ground truth scores the run (`metrics.attitude_errors`).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..drivers.base import GroundTruth, Source
from ..drivers.extrinsics import parse_imu_rotation, with_imu_geometry
from ..drivers.interleave import AccelerometerFeed
from ..errors import InputError, OutputError
from ..backends.base import SteadyPart
from ..backends.factory import backend_kind, knows_gravity
from ..scoring.metrics import attitude_errors, error_summary
from ..scoring.statistics import error_stats
from ..io.safe_files import ENVIRONMENT_ERRNOS, ReservedFile
from ..rotations import align_constant
from ..types import Status
from .config import RunConfig
from ..solver.cues import CueSolver, parse_cues
from .imu_rotation_check import ImuRotationCheck
from .runner import Pipeline, RunStats
from . import stop_signals
from ..sinks.estimate_files import EstimateLog, EstimatesCsvWriter, TumTrajectoryWriter
from .stages import CappedNormals, backend_for_run, make_normal_estimator, mekf_preset_for


OUTPUT_NAMES = ("trajectory.tum", "estimates.csv", "summary.json", "masks", "overlay", "ground.mp4")
"""What run, eval, horizon and ground write in their output folder; `--force` replaces exactly these."""


def prepare_output_folder(out_dir: str | Path, force: bool) -> Path:
    """The output folder, created; a non-empty one is refused unless `force`, which removes the
    results of an earlier run (`OUTPUT_NAMES`) and leaves other files alone."""
    out = make_output_folder(out_dir)
    held = sorted(p.name for p in out.iterdir())
    if held and not force:
        shown = ", ".join(held[:3]) + (f" and {len(held) - 3} more" if len(held) > 3 else "")
        raise InputError(f"--out {out} is not empty (holds {shown}); pass --force to replace the results in it")
    for name in OUTPUT_NAMES if force else ():
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
    return out


@contextmanager
def output_folder(out_dir: str | Path, force: bool) -> Iterator[Path]:
    """`prepare_output_folder`, and when the block fails with the folder still empty (a source that
    does not open, a bad setting), the folders it created are removed again: a failed run leaves no
    empty --out behind. A folder that existed before, or holds anything, is kept."""
    out = Path(out_dir)
    created = [p for p in (out, *out.parents) if not p.exists() and not p.is_symlink()]
    folder = prepare_output_folder(out, force)
    try:
        yield folder
    except BaseException:
        for path in created:  # the deepest first; stops at the first that holds something
            try:
                path.rmdir()
            except OSError:
                break
        raise


def make_output_folder(out_dir: str | Path) -> Path:
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a read-only or full file system is the environment's (exit 1), not the user's
        error = OutputError if exc.errno in ENVIRONMENT_ERRNOS else InputError
        raise error(f"{out}: cannot create the output folder ({exc.strerror or exc})") from None
    return out


def visual_stages(cfg: RunConfig, info) -> tuple[CappedNormals | None, CueSolver]:
    """The normal estimator of `cfg` (None without the normals cue) and its cue solver, for a source
    with frames described by `info` (`run` and `compare` build them here alike)."""
    chosen = parse_cues(cfg.cues)
    normals = (CappedNormals(make_normal_estimator(cfg.normals, info, cfg.threads), cfg.kappa_cap)
               if "normals" in chosen else None)
    return normals, CueSolver(lines="lines" in chosen, assumed_fov_deg=cfg.assumed_fov_deg, sky="sky" in chosen,
                              image_normals=cfg.normals != "depth")


def build_pipeline(source: Source, cfg: RunConfig, sinks: Iterable = ()) -> Pipeline:
    normals, cues = visual_stages(cfg, source.info) if source.info.has_frames else (None, None)
    backend = backend_for_run(cfg, source.info)
    if cfg.offline:
        from ..backends.mekf.offline import offline_backend

        if cfg.backend != "mekf":
            raise InputError(f"--offline smooths with the mekf backend, not {cfg.backend}")
        backend = offline_backend(backend.config, source)
    pipeline = Pipeline(normals, backend, sinks, cues)
    if accelerometer_used(source, cfg):
        pipeline.accelerometer = AccelerometerFeed(*source.accelerometer, source.info.imu_time_offset_s)
        pipeline.steady = SteadyPart(from_stream=False)  # gravity fused beside the frames: the calibration's steady part
    return pipeline


def accelerometer_used(source: Source, cfg: RunConfig) -> bool:
    """Whether a run feeds the source's accelerometer without gyro to its backend (the EKF only)."""
    return source.accelerometer is not None and cfg.accelerometer and cfg.backend == "mekf" and not cfg.offline


def accelerometer_note(source: Source, cfg: RunConfig) -> str | None:
    """The `note:` line on an accelerometer without gyro: used as gravity only, or why not."""
    if source.accelerometer is None:
        return None
    what = f"{source.info.name}: accelerometer without gyro"
    if accelerometer_used(source, cfg):
        axes = getattr(source, "accelerometer_axes_from", None) or "the source's R_ci"
        return f"{what}: used as gravity only (axes: {axes}; --imu-rotation overrides, --no-accel leaves it out)"
    why = "--no-accel" if not cfg.accelerometer else f"the {cfg.backend} backend takes none"
    return f"{what}: not used ({why})"


def run_source(source: Source, out: Path, cfg: RunConfig, evaluate: bool = False, extra_sinks: Iterable = (),
               on_result: Callable | None = None, command: str = "run") -> dict:
    """Run an opened source into `out` (an existing folder): `trajectory.tum` (t s, `R_wc` as
    quaternion x y z w), `estimates.csv` (covariance in rad^2, up in the camera frame, status) and
    `summary.json`; returns the summary. `evaluate` scores against the source's ground truth (ARE,
    tilt in deg, NEES); `extra_sinks` get every result; `on_result(result)` is called per result.

    >>> import tempfile
    >>> from pathlib import Path
    >>> from uareme_fusion.drivers import open_source
    >>> from uareme_fusion.pipeline import RunConfig
    >>> with tempfile.TemporaryDirectory() as tmp, open_source("sim:room", seconds=0.5, width=64, height=48) as src:
    ...     summary = run_source(src, Path(tmp), RunConfig(), evaluate=True)
    >>> summary["frames"] > 0 and summary["tilt_deg"]["max"] < 5.0
    True
    """
    truth = source.ground_truth() if evaluate else None
    if evaluate and truth is None:
        raise InputError(f"{source.info.name}: this source has no ground truth to evaluate against "
                         "(use 'uareme-fusion run' instead)")
    extra_sinks = list(extra_sinks)
    log = EstimateLog() if evaluate else None
    pipeline = build_pipeline(source, cfg)  # a bad backend setting stops here, before any file is written
    summary_file = ReservedFile(out / "summary.json", json.dumps({"command": command, "stopped": "running"}) + "\n")
    check = ImuRotationCheck.for_source(source)
    sinks = [TumTrajectoryWriter(out / "trajectory.tum"), EstimatesCsvWriter(out / "estimates.csv"),
             *extra_sinks, *([log] if log else []), *([check] if check else [])]
    pipeline.sinks = sinks
    stats = pipeline.run(source if check is None else check.tap(source), max_frames=cfg.max_frames,
                         on_result=on_result)
    with stop_signals.writing():  # a signal now waits until summary.json is complete
        summary = summary_document(stats, cfg, command, source)
        normals_note = getattr(pipeline.normals, "note", None)
        if normals_note:
            summary["notes"].append(normals_note)
            summary["normals_note"] = normals_note
        if pipeline.accelerometer is not None:  # an accelerometer without gyro: what became of its updates
            summary["accelerometer_counts"] = {k: v for k, v in getattr(pipeline.backend, "counters", {}).items()
                                               if k.startswith("accel_only")}
        if pipeline.cues is not None and pipeline.cues.focal is not None:  # K given, estimated or assumed
            summary["intrinsics"] = pipeline.cues.intrinsics_summary()
        if pipeline.cues is not None and pipeline.cues.sky_cadence is not None:  # `solver/sky_cadence.py`
            summary["sky_detector"] = {"frames": pipeline.cues.sky_cadence.frames, "looked": pipeline.cues.sky_cadence.looks}
        for sink in extra_sinks:
            summary.update(getattr(sink, "summary", dict)())
        if check is not None:
            summary["imu_rotation_estimate"] = check.report()
            refused = check.refused is not None  # the run's error says it
            summary["imu_rotation_estimate"]["refused_to_fuse"] = refused
            summary["warnings"] = [w for w in [check.warning(summary["imu_rotation_estimate"])] if w and not refused]
        if log is not None:
            summary.update(evaluation(log, truth, gravity_aware=knows_gravity(
                backend_kind(cfg.backend, source.info.has_imu).name, source.info.has_imu)))
        summary["outputs"] = sorted(p.name for p in out.iterdir()
                                    if p.name != "summary.json" and not p.name.startswith(".")) + ["summary.json"]
        try:
            summary_file.write(json.dumps(summary, indent=2, sort_keys=False) + "\n")
        except (InputError, OutputError) as exc:
            summary["summary_error"] = str(exc)
    return summary


def configure_imu(source: Source, cfg: RunConfig) -> Source:
    """`source` with the configuration's camera-IMU rotation and time offset, when given, in place
    of its own (`RunConfig.imu_rotation`, `imu_time_offset_s`); call before the source runs."""
    R_ci = None if cfg.imu_rotation is None else parse_imu_rotation(cfg.imu_rotation)
    return with_imu_geometry(source, R_ci, cfg.imu_time_offset_s)


def open_for_run(source_spec: str, cfg: RunConfig, imu: str | Path | None = None, fps: float | None = None,
                 gt: Path | None = None, gt_time_offset_s: float | None = None, topics: dict | None = None) -> Source:
    """The source as `run` opens it: `imu` merged, the configuration's K, camera-IMU rotation and time
    offset, a ground-truth file `gt` in place of its own (its stamps + `gt_time_offset_s`, 0 when None),
    or without `gt` its own ground truth shifted by `gt_time_offset_s` in place of its default, and a ROS
    bag's `topics` (`image_topic`, ... as `open_source` takes them; None values are left to the bag)."""
    from ..drivers import open_source

    opened = configure_imu(open_source(str(source_spec), imu=None if imu is None else str(imu), fps=fps,
                                       intrinsics=cfg.intrinsics, **(topics or {})), cfg)
    if gt is not None:
        from ..drivers.ground_truth_file import with_ground_truth_file

        with_ground_truth_file(opened, gt, gt_time_offset_s or 0.0)
    elif gt_time_offset_s is not None:
        from ..drivers.ground_truth_file import with_ground_truth_time_offset

        with_ground_truth_time_offset(opened, gt_time_offset_s)
    return opened


def run_into_folder(source_spec: str, out_dir: Path, cfg: RunConfig, force: bool = False) -> dict:
    """`uareme-fusion run SOURCE --out DIR` without its terminal output (a batch's worker): the same
    folder rules (`output_folder`), source (`open_for_run`) and run (`run_source`); the summary."""
    with output_folder(out_dir, force) as out, open_for_run(source_spec, cfg) as source:
        return run_source(source, out, cfg, command="run")


def run_to_folder(source_spec: str, out_dir: str | Path, cfg: RunConfig | None = None, imu: str | None = None,
                  evaluate: bool = False, on_result: Callable | None = None, extra_sinks: Iterable = (),
                  command: str = "run", **source_options) -> dict:
    """Open `source_spec` (see `drivers.open_source`), run it, write the outputs; returns the summary."""
    from ..drivers import open_source

    cfg = cfg or RunConfig()
    out = make_output_folder(out_dir)
    with open_source(str(source_spec), imu=imu, intrinsics=cfg.intrinsics, **source_options) as source:
        configure_imu(source, cfg)
        return run_source(source, out, cfg, evaluate, extra_sinks, on_result, command)


def run_notes(source: Source, cfg: RunConfig) -> tuple[list[str], list[str]]:
    """(notes, fixes) of a run: what the source's driver left out or repaired, and the preset choice."""
    notes, fixes = source.report()
    notes += [note for note in [accelerometer_note(source, cfg)] if note]
    if cfg.backend == "mekf":
        _, preset_note = mekf_preset_for(cfg.mekf_preset, source.info)
        notes += [preset_note] if preset_note else []
    return notes, fixes


def summary_document(stats: RunStats, cfg: RunConfig, command: str, source: Source) -> dict:
    info = source.info
    notes, fixes = run_notes(source, cfg)
    doc = {"command": command, **stats.as_dict(),
           "source_info": {"frames_known": info.n_frames, "fps": info.fps, "has_frames": info.has_frames,
                           "has_imu": info.has_imu, "has_depth": info.has_depth,
                           "accelerometer_used": accelerometer_used(source, cfg),
                           "intrinsics_known": info.K is not None, "intrinsics_from": info.K_origin},
           "mekf_preset": mekf_preset_for(cfg.mekf_preset, info)[0] if cfg.backend == "mekf" else None,
           "notes": notes, "input_fixes": fixes,
           "config": cfg.model_dump(mode="json")}
    return doc


def evaluation(log: EstimateLog, truth: GroundTruth, gravity_aware: bool) -> dict:
    """ARE, tilt and NEES against `truth` over initialised estimates inside its time span
    (`evaluation_errors`), summarised; with a reference that is not gravity-aligned, also
    `tilt_unaligned_deg`: the tilt against the reference's z axis without the alignment."""
    t, errors, unaligned_tilt, note = evaluation_errors(log, truth, gravity_aware)
    if len(t) == 0:
        return {"evaluation_note": note, **error_summary(errors)}
    out = {**error_summary(errors), "evaluation_note": note}
    if unaligned_tilt is not None and errors["valid"].any():
        out["tilt_unaligned_deg"] = error_stats(unaligned_tilt[errors["valid"]], ("mean", "rmse", "p95", "max"))
    return out


def evaluation_errors(log: EstimateLog, truth: GroundTruth, gravity_aware: bool):
    """(t_s (N,), per-frame errors (`metrics.attitude_errors`: `are_deg`, `tilt_deg`, `nees`, `valid`),
    tilt (N,) without alignment or None, note) of the estimates in `log` against `truth`; `valid`:
    initialised estimates inside its time span.

    Without a gravity-aligned reference (e.g. ICL-NUIM) tilt is measured after the same constant
    alignment as ARE, since the reference world's z is not up; the tilt against its z axis without
    the alignment is returned beside it.
    """
    t, R_est, cov, status = log.arrays()
    if len(t) == 0:
        empty = {"valid": np.zeros(0, bool), "are_deg": np.zeros(0), "tilt_deg": np.zeros(0), "nees": np.zeros(0)}
        return t, empty, None, "no estimates to score"
    R_true, in_span = truth.at(t)
    valid = in_span & ((status & int(Status.NOT_INITIALISED)) == 0)
    note, unaligned_tilt = "tilt against the reference's z axis (gravity-aligned)", None
    if not truth.gravity_aligned and valid.any():
        unaligned_tilt = attitude_errors(R_est, cov, valid, R_true)["tilt_deg"]
        R_est = align_constant(R_est[valid], R_true[valid]) @ R_est
        note = "reference is not gravity-aligned: tilt after the constant alignment used for ARE"
    errors = attitude_errors(R_est, cov, valid, R_true, yaw_only_nees=gravity_aware and truth.gravity_aligned,
                             cov_steady_rad2=log.steady())
    return t, errors, unaligned_tilt, note
