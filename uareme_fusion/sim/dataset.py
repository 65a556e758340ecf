"""Write a simulated sequence to disk in formats users already have.

    summary = write_sequence("room", Path("out"), SequenceOptions(frames=100), progress=callback)

Layout of `out/` (TUM RGB-D plus EuRoC IMU plus ground truth):
- `rgb/<t>.png` 8-bit RGB images; `depth/<t>.png` 16-bit depth, `DEPTH_SCALE` (5000) units per
  metre as in TUM RGB-D and ICL-NUIM, 0 = no depth; `<t>` is the timestamp with 6 decimals.
- `rgb.txt`, `depth.txt`: `timestamp filename` per line, `#` comments first (TUM format).
- `groundtruth.txt`: `timestamp tx ty tz qx qy qz qw` (TUM): camera centre in the world (m) and the
  orientation `R_wc` (camera OpenCV axes to world, z up) as a unit quaternion, order x y z w.
- `accelerometer.txt`: `timestamp ax ay az` (TUM), specific force in the IMU frame, m/s^2, at the
  IMU rate, IMU clock.
- `imu0/data.csv`: EuRoC: `#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]`, gyro in
  rad/s and specific force in m/s^2 in the IMU frame, integer nanoseconds, IMU clock.
- `normals/<index:06d>.npz`: `normals` (H, W, 3) float32 unit normals in the camera frame,
  `kappa` (H, W) float32 (`GT_KAPPA` where a surface was hit, 0 elsewhere), `mask` (H, W) bool
  Manhattan-aligned pixels, `R_wc`, `R_wm` (3, 3), `K` (3, 3), `t` (s), `dropped` (bool).
- `scene.json`: seed, scenario, every scene/trajectory/IMU/render parameter, K, R_ci, time offset,
  the dropped frame indices and, for the bus, `R_wm` per frame as quaternions x y z w.
- `simulate.incomplete`: present only while the sequence is being written (an interrupted
  `simulate` leaves it, and `run` refuses the folder saying so; `incomplete_simulation`).
Frames are timestamped `index / fps` seconds on the camera clock. Same seed, identical files
(PNG, npz with fixed zip dates, sorted JSON).
"""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..formats.datasets import GT_KAPPA
from ..formats.depth_png import TUM_DEPTH_SCALE, depth_png_units
from ..formats.euroc import write_euroc_imu
from ..formats.tum import TUM_TRAJECTORY_HEADER, tum_list_text, write_tum_table
from ..io.safe_files import write_bytes_atomic, write_image_atomic, write_text_atomic
from .imu import simulate_imu
from .options import SequenceOptions
from .render import Renderer, intrinsics_from_fov
from .scenarios import SCENARIOS, build_scenario

DEPTH_SCALE = TUM_DEPTH_SCALE
"""Depth PNG units per metre (TUM RGB-D / ICL-NUIM convention)."""
INCOMPLETE_MARKER = "simulate.incomplete"
"""The file that says a folder is still being written by `simulate` (removed once it is complete)."""


def incomplete_simulation(folder: Path) -> str | None:
    """'an interrupted simulate (N of M frames written)' for a folder `simulate` did not finish; None
    for any other folder."""
    marker = Path(folder) / INCOMPLETE_MARKER
    if not marker.is_file():
        return None
    try:
        total = json.loads(marker.read_text())["frames"]
    except (OSError, ValueError, KeyError, TypeError):
        total = "?"
    done = len(list((Path(folder) / "normals").glob("*.npz")))
    return f"an interrupted 'simulate' ({done} of {total} frames written, no index or IMU files)"


def _save_npz(path: Path, **arrays) -> None:
    """Uncompressed-array npz with fixed zip dates, so identical inputs give identical bytes."""
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, value in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(value), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, buf.getvalue())
    write_bytes_atomic(path, archive.getvalue())


def prepare_out_dir(out_dir: Path, force: bool) -> None:
    """Create `out_dir`; refuse a non-empty one unless `force` (then its old files are replaced)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"--out {out_dir} exists and is not a folder")
    if out_dir.exists() and any(out_dir.iterdir()) and not force:
        raise InputError(f"--out {out_dir} is not empty; pass --force to overwrite it")
    out_dir.mkdir(parents=True, exist_ok=True)
    for sub in ("rgb", "depth", "normals", "imu0"):  # only what write_sequence itself writes
        if force and (out_dir / sub).is_dir():
            shutil.rmtree(out_dir / sub)
    if force and (out_dir / INCOMPLETE_MARKER).exists():
        (out_dir / INCOMPLETE_MARKER).unlink()


def write_sequence(scenario: str, out_dir: Path, options: SequenceOptions,
                   progress: Callable[[int, int], None] | None = None) -> dict:
    """Simulate `scenario` and write it under `out_dir` (see the module docstring).

    `progress(done, total)` is called after every frame. Returns a summary dict (also the core of
    scene.json).
    """
    options.validate()
    if scenario not in SCENARIOS:
        raise InputError(f"unknown scenario {scenario!r}; valid: {', '.join(SCENARIOS)}")
    out = Path(out_dir)
    spec = SCENARIOS[scenario]
    duration_s = (options.frames - 1) / options.fps if options.frames > 1 else 1.0 / options.fps
    world = build_scenario(scenario, duration_s, options.seed)
    hfov = spec.hfov_deg if options.hfov_deg is None else options.hfov_deg
    K = intrinsics_from_fov(options.width, options.height, hfov)
    renderer = Renderer(world.scene, K, options.width, options.height)
    rng = np.random.default_rng([options.seed, 7])  # image noise, exposure, drops
    for sub in ("rgb", "depth", "normals", "imu0"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / INCOMPLETE_MARKER, json.dumps({
        "frames": options.frames, "scenario": scenario,
        "note": "uareme-fusion simulate is writing this folder, or was stopped before it finished; "
                "run it again with --force"}) + "\n")

    t_frames = np.arange(options.frames) / options.fps
    dropped = rng.random(options.frames) < spec.drop_probability
    gains = np.ones(options.frames)
    if spec.exposure_change:
        walk = np.cumsum(rng.normal(0.0, 0.08, options.frames))
        gains = np.exp(np.clip(walk - walk.mean(), -0.7, 0.5))
    stamps = [f"{t:.6f}" for t in t_frames]
    R_wm_all = []
    for i, t in enumerate(t_frames):
        radiance, depth, normals_c, mask, R_wc, p_w = world.render_radiance(renderer, t)
        if spec.motion_blur_exposure_s > 0:  # average sub-frames over the exposure
            subs = t + np.linspace(-0.5, 0.5, 5) * spec.motion_blur_exposure_s
            radiance = np.mean([world.render_radiance(renderer, ts)[0] for ts in subs], axis=0)
        rgb = Renderer.to_uint8(radiance, gains[i], spec.noise_std_dn, rng)
        depth_png = depth_png_units(depth, DEPTH_SCALE)[0]
        if dropped[i]:
            rgb[:] = 0
            depth_png[:] = 0
        write_image_atomic(out / "rgb" / f"{stamps[i]}.png", np.ascontiguousarray(rgb[..., ::-1]))
        write_image_atomic(out / "depth" / f"{stamps[i]}.png", depth_png)
        R_wm = world.trajectory.R_wm(t)[0]
        R_wm_all.append(R_wm)
        _save_npz(out / "normals" / f"{i:06d}.npz", normals=normals_c,
                  kappa=np.where(depth > 0, GT_KAPPA, 0.0).astype(np.float32), mask=mask,
                  R_wc=R_wc, R_wm=R_wm, K=K, t=np.float64(t), dropped=np.bool_(dropped[i]))
        if progress is not None:
            progress(i + 1, options.frames)

    sample = world.trajectory.sample(t_frames)
    quat = Rotation.from_matrix(sample.R_wc).as_quat(canonical=True)
    write_tum_table(out / "groundtruth.txt", "ground truth trajectory (R_wc: camera OpenCV axes to world z up)"
                    "\n" + TUM_TRAJECTORY_HEADER, t_frames, np.column_stack([sample.p_w, quat]),
                 "%.6f")
    for kind in ("rgb", "depth"):
        write_text_atomic(out / f"{kind}.txt", tum_list_text(f"{kind} images (simulated, scenario {scenario}, seed "
                                                             f"{options.seed})", stamps, [f"{kind}/{s}.png" for s in stamps]))
    R_ci = np.asarray(options.R_ci, float)
    t_imu, gyro, accel = simulate_imu(world.trajectory, options.imu_rate_hz, options.imu_noise,
                                      seed=options.seed, R_ci=R_ci, imu_time_offset_s=options.imu_time_offset_s)
    write_tum_table(out / "accelerometer.txt", "accelerometer data (specific force in the IMU frame, m/s^2)"
                 "\ntimestamp ax ay az", t_imu, accel, "%.9f")
    write_euroc_imu(out / "imu0" / "data.csv", t_imu, gyro, accel)

    summary = dict(
        scenario=scenario, platform=spec.platform, seed=options.seed, frames=options.frames, fps=options.fps,
        width=options.width, height=options.height, hfov_deg=hfov, K=K.tolist(),
        depth_scale=DEPTH_SCALE, gt_kappa=GT_KAPPA, imu_rate_hz=options.imu_rate_hz,
        imu_noise=options.imu_noise.as_dict(), R_ci=R_ci.tolist(), imu_time_offset_s=options.imu_time_offset_s,
        spec=asdict(spec), dropped_frames=np.flatnonzero(dropped).tolist(),
        exposure_gains=[round(float(g), 6) for g in gains],
        trajectory=world.trajectory.params, scene=world.scene.as_dict(),
        manhattan_frame="bus body (moves)" if world.trajectory.manhattan_is_body else "world axes (fixed)",
        R_wm_quat_xyzw=Rotation.from_matrix(np.stack(R_wm_all)).as_quat(canonical=True).round(9).tolist(),
        conventions=("R_wc maps camera (OpenCV x right, y down, z forward) to world (z up); "
                     "quaternions x y z w; accel is specific force (+9.81 up at rest); "
                     "IMU stamp t measures camera time t + imu_time_offset_s; v_c = R_ci v_i"),
    )
    write_text_atomic(out / "scene.json", json.dumps(summary, indent=1, sort_keys=True, default=float))
    (out / INCOMPLETE_MARKER).unlink()
    return summary
