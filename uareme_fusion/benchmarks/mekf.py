"""Benchmark of the multiplicative EKF (issue 5): accuracy, consistency and cost, peers in the same run.

    uareme-fusion bench mekf [--seeds 5] [--quick] [--data ../shared/data/broad_subset]
    uareme-fusion bench mekf --run-cost    # whole `run` on each IMU-only file beside vqf and imufusion

Prints, per scenario, absolute figures:
- bus (camera fixed in a city bus): fused tilt error p95 / max (deg) over 5 seeds, beside vqf 6D,
  imufusion and ahrs Madgwick / Mahony run on the same IMU data;
- handheld walk in a room with 20 % dropped frames (visual=None): max and mean ARE (deg) of mekf
  and of the `single` backend;
- mean NEES of the fused attitude (after one constant alignment of the world) on those runs;
- BROAD (IMU-only, movement samples): inclination RMSE of mekf and vqf 6D per trial and their ratio;
  again against the reference re-timed to the IMU's delay (`reference_timing`; the same for all);
- EuRoC V1_02, first 40 s (IMU-only, large gyro bias): tilt RMSE of mekf (online and offline) and
  vqf 6D against the ground truth on the same samples;
- issue 17 goals beside each figure: BROAD online <= 0.95 x vqf 6D per trial, offline
  (`mekf.offline.forward_backward_imu`) <= 0.85 x, EuRoC <= 1.0 x; IMU-only library batch
  <= 1 us/sample and whole `run` on a BROAD file <= 2 us/sample, with vqf's and imufusion's
  cost on the same samples in the same run; fused 200 Hz IMU at 30 fps <= 3 us per IMU sample;
- cost: us per IMU sample (IMU-only on BROAD; in the fused runs all the filter does but the visual
  update proper, and with it, on replays of the runs, in a loop and between solver calls: see
  `fused_cost`) and ms per visual update
  (the filter only, not the solver). Timings are medians of repeated runs on a shared machine: the
  fused ones in wall time (a CPU-time read costs about as much as the filter's frame), the others in
  CPU time of the filter's thread (`time.thread_time`: what the filter itself costs, whatever else
  the machine runs) with wall-clock time beside it (equal on an idle machine, inflated when shared).

Scenarios (trajectory, IMU, the real solver's rotations) come from `evaluation.scenarios`; BROAD
trials from `--data`, EuRoC V1_02's first 40 s from `euroc_v1_02_first40s/mav0` beside that folder.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..backends.mekf import Mekf, MekfConfig
from ..backends.mekf.filter import load_kernels
from ..backends.mekf.offline import forward_backward_imu
from ..backends.single import SingleFrame
from ..config import load_config
from ..formats.broad import read_broad
from ..evaluation.scenarios import RunResult, run_scenario
from ..scoring.statistics import error_stats, rmse
from ..rotations import tilt_error_deg, up_in_camera
from .fused_cost import REPLAYS, fused_cost_us, recording_mekf_factory
from .peers import vqf_6d_R_wi
from .reference_timing import imu_delay_s, retimed_reference

EUROC_BESIDE_BROAD = Path("euroc_v1_02_first40s") / "mav0"
"""EuRoC V1_02's first 40 s, in the folder holding the BROAD folder (`../shared/data`)."""
REPLAY_LABELS = {"loop": "in a loop:", "between_solver": "between solver calls:"}
GOALS = {"online": 0.95, "offline": 0.85, "euroc": 1.0, "batch_us": 1.0, "run_us": 2.0, "fused_us": 3.0}
"""Issue 17: ratios to vqf 6D (accuracy) and us per IMU sample (cost)."""
# Same settings on every BROAD trial: the `imu_only` preset (accelerometer low-passed in the
# gyro-carried frame, zero-rate bias updates at rest, rate-proportional gyro noise).
BROAD_PRESET = "imu_only"


def peer_tilt_errors(t_imu, gyro, accel, traj, rate_hz: float) -> dict[str, np.ndarray]:
    """Tilt error (deg) per IMU sample of IMU-only peers (IMU frame = camera frame here)."""
    import ahrs
    import imufusion

    up_true = up_in_camera(traj.sample(t_imu).R_wc)
    errors = {"vqf 6D": tilt_error_deg(up_in_camera(vqf_6d_R_wi(gyro, accel, 1.0 / rate_hz)), up_true)}
    out = {}
    out["madgwick"] = ahrs.filters.Madgwick(gyr=gyro, acc=accel, frequency=rate_hz).Q
    out["mahony"] = ahrs.filters.Mahony(gyr=gyro, acc=accel, frequency=rate_hz).Q
    # imufusion takes deg/s and g; settings as in its README example (10 deg rejection, 5 s timeout).
    fusion = imufusion.Ahrs()
    settings = imufusion.AhrsSettings()
    settings.sample_rate = int(rate_hz)
    settings.acceleration_rejection = 10.0
    settings.rejection_timeout = int(5 * rate_hz)
    fusion.set_settings(settings)
    fusion.set_sample_period(1.0 / rate_hz)
    gyro_deg_s, accel_g = np.degrees(gyro), accel / 9.81
    q = np.empty((t_imu.size, 4))
    for i in range(t_imu.size):
        fusion.update_no_magnetometer(gyro_deg_s[i], accel_g[i])
        q[i] = fusion.get_quaternion()
    out["imufusion"] = q
    for name, q in out.items():
        R_wi = Rotation.from_quat(q, scalar_first=True).as_matrix()
        errors[name] = tilt_error_deg(up_in_camera(R_wi), up_true)
    return errors


def imu_only_run(config: MekfConfig, t_s, gyro, accel, offline: bool = False):
    """(t (M,), R_wc (M, 3, 3), CPU us per sample) of one IMU-only run in one library call."""
    c0 = time.thread_time()
    if offline:
        t_rec, R_rec = forward_backward_imu(config, t_s, gyro, accel)
    else:
        filt = Mekf(config.model_copy(update={"mode": "imu_only", "record_imu_estimates": True}))
        filt.process_imu(t_s, gyro, accel)
        filt.flush()
        t_rec, R_rec = filt.imu_trajectory()
    return t_rec, R_rec, 1e6 * (time.thread_time() - c0) / np.size(t_s)


def tilt_rmse_on(t_s, t_rec, R_rec, R_ref, keep) -> float:
    """Tilt RMSE (deg) of recorded estimates against `R_ref` (N, 3, 3) on the samples `keep` (N,)."""
    idx = np.searchsorted(t_s, t_rec)
    ok = keep[idx] & np.all(np.isfinite(R_ref[idx]), axis=(1, 2))
    return rmse(tilt_error_deg(up_in_camera(R_rec[ok]), up_in_camera(R_ref[idx][ok])))


def broad_runs(trial, config: MekfConfig) -> tuple:
    """The estimates scored on one BROAD trial: (mekf online (t, R), mekf offline (t, R), vqf 6D R (N, 3, 3),
    mekf us/sample)."""
    t = trial.t_s
    t_on, R_on, us = imu_only_run(config, t, trial.gyro_rad_s, trial.accel_m_s2)
    t_off, R_off, _ = imu_only_run(config, t, trial.gyro_rad_s, trial.accel_m_s2, offline=True)
    R_vqf = vqf_6d_R_wi(trial.gyro_rad_s, trial.accel_m_s2, 1.0 / trial.sampling_rate_hz)
    return (t_on, R_on), (t_off, R_off), R_vqf, us


def broad_scores(trial, runs: tuple, retimed: bool = False) -> tuple[float, float, float, float]:
    """(mekf online, mekf offline, vqf 6D inclination RMSE deg over the movement samples, mekf us/sample)
    of `broad_runs`. With `retimed`, all three against the optical reference read the IMU's delay
    earlier (`reference_timing.imu_delay_s`) instead of the published index pairing."""
    (t_on, R_on), (t_off, R_off), R_vqf, us = runs
    t, R_ref, keep = trial.t_s, trial.R_ref_imu, trial.movement
    if retimed:
        R_ref = retimed_reference(t, R_ref, imu_delay_s(t, trial.gyro_rad_s, R_ref, keep))
    return (tilt_rmse_on(t, t_on, R_on, R_ref, keep), tilt_rmse_on(t, t_off, R_off, R_ref, keep),
            tilt_rmse_on(t, t, R_vqf, R_ref, keep), us)


def broad_inclination(trial, config: MekfConfig, retimed: bool = False) -> tuple[float, float, float, float]:
    """`broad_scores` of `broad_runs`: the filters run and scored on one trial."""
    return broad_scores(trial, broad_runs(trial, config), retimed)


def euroc_tilt(config: MekfConfig, euroc_dir: Path) -> tuple[float, float, float]:
    """(mekf online, mekf offline, vqf 6D) tilt RMSE deg on EuRoC V1_02's first 40 s, at the ground
    truth's times (its body frame is the IMU frame)."""
    from ..formats.euroc import read_euroc_imu

    imu = read_euroc_imu(euroc_dir / "imu0" / "data.csv")
    gt = np.loadtxt(euroc_dir / "gt0" / "data.csv", delimiter=",", comments="#")
    t = imu.t_s
    idx = np.searchsorted(t, gt[:, 0] * 1e-9)
    inside = idx < t.size
    R_ref = np.full((t.size, 3, 3), np.nan)
    R_ref[idx[inside]] = Rotation.from_quat(gt[inside, 4:8], scalar_first=True).as_matrix()
    keep = np.isfinite(R_ref[:, 0, 0])
    t_on, R_on, _ = imu_only_run(config, t, imu.gyro_rad_s, imu.accel_m_s2)
    t_off, R_off, _ = imu_only_run(config, t, imu.gyro_rad_s, imu.accel_m_s2, offline=True)
    R_vqf = vqf_6d_R_wi(imu.gyro_rad_s, imu.accel_m_s2, float(np.median(np.diff(t))))
    return (tilt_rmse_on(t, t_on, R_on, R_ref, keep), tilt_rmse_on(t, t_off, R_off, R_ref, keep),
            tilt_rmse_on(t, t, R_vqf, R_ref, keep))


def peer_cost_us(gyro, accel, rate_hz: float) -> dict[str, float]:
    """CPU us per sample of vqf 6D (one batch call) and imufusion (its per-sample loop) on these samples."""
    import imufusion
    from vqf import VQF

    c0 = time.thread_time()
    VQF(1.0 / rate_hz).updateBatch(np.ascontiguousarray(gyro), np.ascontiguousarray(accel))
    out = {"vqf": 1e6 * (time.thread_time() - c0) / len(gyro)}
    fusion = imufusion.Ahrs()
    fusion.set_sample_period(1.0 / rate_hz)
    gyro_deg_s, accel_g = np.degrees(gyro), accel / 9.81
    c0 = time.thread_time()
    for i in range(len(gyro)):
        fusion.update_no_magnetometer(gyro_deg_s[i], accel_g[i])
    out["imufusion"] = 1e6 * (time.thread_time() - c0) / len(gyro)
    return out


def run_command_cost_us(path: Path) -> tuple[float, float, int]:
    """(CPU us, wall us per IMU sample, samples) of `uareme-fusion run FILE` (whole pipeline: source,
    filter, file sinks) in this process, after the source is opened (the file read) and the kernels
    loaded; the median of three runs."""
    import tempfile

    from ..drivers.registry import open_source
    from ..pipeline import RunConfig
    from ..pipeline.session import build_pipeline
    from ..sinks.estimate_files import EstimatesCsvWriter, TumTrajectoryWriter

    cpu, wall = [], []
    for _ in range(3):
        with tempfile.TemporaryDirectory() as tmp, open_source(str(path)) as source:
            out = Path(tmp)
            sinks = [TumTrajectoryWriter(out / "trajectory.tum"), EstimatesCsvWriter(out / "estimates.csv")]
            pipeline = build_pipeline(source, RunConfig(), sinks)
            t0, c0 = time.perf_counter(), time.thread_time()
            n = pipeline.run(source).imu_samples
            cpu.append(1e6 * (time.thread_time() - c0) / n)
            wall.append(1e6 * (time.perf_counter() - t0) / n)
    return float(np.median(cpu)), float(np.median(wall)), n


def imu_file_arrays(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """(gyro, accel, rate Hz) of a BROAD .hdf5 or an EuRoC imu0 csv."""
    if path.suffix == ".hdf5":
        trial = read_broad(path)
        return trial.gyro_rad_s, trial.accel_m_s2, trial.sampling_rate_hz
    from ..formats.euroc import read_euroc_imu

    imu = read_euroc_imu(path)
    return imu.gyro_rad_s, imu.accel_m_s2, 1.0 / float(np.median(np.diff(imu.t_s)))


def print_run_costs(broad_dir: Path, euroc_dir: Path) -> dict:
    """Whole `run` on every IMU-only file (BROAD trials, EuRoC imu0), beside vqf 6D and imufusion on
    the same samples in the same process; {file name: CPU us per sample}."""
    paths = sorted(broad_dir.glob("*.hdf5")) + [euroc_dir / "imu0" / "data.csv"]
    costs = {}
    print(f"== whole `run` on IMU-only files, CPU us per IMU sample (wall) [goal <= {GOALS['run_us']:g}] ==")
    for path in paths:
        if not path.is_file():
            continue
        cpu, wall, n = run_command_cost_us(path)
        peers = peer_cost_us(*imu_file_arrays(path))
        print(f"  {path.parent.name + '/' + path.name if path.suffix == '.csv' else path.name:42s} {n:6d} samples: "
              f"run {cpu:5.2f} ({wall:5.2f}) | vqf 6D {peers['vqf']:5.2f} | imufusion {peers['imufusion']:5.2f}")
        costs[path.name] = cpu
    return {"run_us": costs}


def run(seeds: int = 5, quick: bool = False, broad_dir: Path = Path("../shared/data/broad_subset"),
        run_cost: bool = False) -> dict:
    """Print the figures (see the module docstring) and return the headline ones; `quick`: shorter
    simulated runs (not the reported figures); `run_cost`: only the whole-`run` cost on the IMU-only files."""
    euroc_dir = Path(broad_dir).parent / EUROC_BESIDE_BROAD
    for with_frames in (False, True):  # from numba's disk cache, or compiled, before anything is timed
        load_kernels(with_frames)
    if run_cost:
        return print_run_costs(Path(broad_dir), euroc_dir)
    seeds = range(seeds)
    bus_s, room_s = (40.0, 20.0) if quick else (90.0, 40.0)
    nees_all = []
    imu_us: dict[str, list[float]] = {"broad": []}  # CPU time
    fused_us: dict[str, list] = {"handheld": [], "bus": []}  # ({way: (without, with the visual update)}, per frame)
    vis_ms, vis_wall_ms = [], []

    made: list = []  # the filters of the fused runs, which record what they were fed (`fused_cost`)

    def record_cost(scenario: str, res: RunResult) -> None:
        inputs = made[-1].inputs
        per_frame = inputs.n_imu / max(len(inputs.frames), 1)  # IMU samples per frame
        fused_us[scenario].append((fused_cost_us(inputs, made[-1].config), per_frame))
        vis_ms.append(1e3 * res.visual_cpu_s / max(res.n_visual, 1))
        vis_wall_ms.append(1e3 * res.visual_time_s / max(res.n_visual, 1))

    print(f"== bus ({bus_s:.0f} s, 15 fps, IMU 200 Hz), tilt error deg ==")
    peers: dict[str, list] = {}
    fused = []
    for seed in seeds:
        res = run_scenario("bus", seed, bus_s, recording_mekf_factory("vehicle", made), fps=15.0)
        fused.append(res.tilt_deg)
        nees_all.append(res.nees(yaw_fit_s=1.0))
        record_cost("bus", res)
        e = error_stats(res.tilt_deg, ("p95", "max"))
        print(f"  seed {seed}: mekf p95 {e['p95']:.2f} max {e['max']:.2f} mean NEES {nees_all[-1].mean():.2f}")
        for name, err in peer_tilt_errors(*res.imu[:3], res.imu[3], 200.0).items():
            peers.setdefault(name, []).append(err)
    figures = {"bus_tilt_deg": {"mekf (fused)": error_stats(np.concatenate(fused), ("p95", "max"))}}
    figures["bus_tilt_deg"].update({name: error_stats(np.concatenate(errs), ("p95", "max"))
                                    for name, errs in peers.items()})
    for name, e in figures["bus_tilt_deg"].items():
        goal = "   [goal p95 <= 1.0, max <= 2.0]" if name == "mekf (fused)" else ""
        print(f"  {name:13s} p95 {e['p95']:6.2f}  max {e['max']:6.2f}{goal}")

    print(f"== handheld walk in a room ({room_s:.0f} s, 30 fps, 20 % frames dropped), ARE deg ==")
    for seed in seeds:
        res = run_scenario("walk", seed, room_s, recording_mekf_factory("handheld", made), drop_fraction=0.2)
        single = run_scenario("walk", seed, room_s, SingleFrame, drop_fraction=0.2, use_imu=False)
        nees_all.append(res.nees())
        record_cost("handheld", res)
        a, b = res.are_deg, single.are_deg
        print(f"  seed {seed}: mekf max {a.max():5.2f} mean {a.mean():5.3f} | single max {b.max():6.2f} "
              f"mean {b.mean():5.3f} | NEES {res.nees().mean():.2f}   [goal max <= 10, mean <= single]")

    n = np.concatenate(nees_all)
    figures["mean_nees"] = error_stats(n, ("mean",))["mean"]
    print(f"== consistency: mean NEES {figures['mean_nees']:.2f} over {n.size} frames [goal 1.5 .. 6]")

    peer_us: dict[str, list[float]] = {"vqf": [], "imufusion": []}
    run_us = run_wall_us = float("nan")
    config = load_config(BROAD_PRESET, MekfConfig)
    broad_dir = Path(broad_dir)
    if broad_dir.is_dir():
        print("== BROAD IMU-only, inclination RMSE deg over movement samples, ratio to vqf 6D "
              f"[goal online <= {GOALS['online']}, offline <= {GOALS['offline']}] ==")
        print(f"  settings (all trials): configs/{BROAD_PRESET}.yaml")
        for path in sorted(broad_dir.glob("*.hdf5")):
            trial = read_broad(path)
            runs = broad_runs(trial, config)
            online, offline, vqf_rmse, us = broad_scores(trial, runs)
            figures.setdefault("broad_tilt_rmse_deg", {})[path.stem] = {"online": online, "offline": offline,
                                                                         "vqf_6d": vqf_rmse}
            imu_us["broad"].append(us)
            for name, value in peer_cost_us(trial.gyro_rad_s, trial.accel_m_s2, trial.sampling_rate_hz).items():
                peer_us[name].append(value)
            print(f"  {path.stem:34s} vqf6D {vqf_rmse:5.2f} | online {online:5.2f} ratio {online / vqf_rmse:4.2f} "
                  f"[<= {GOALS['online']}] | offline {offline:5.2f} ratio {offline / vqf_rmse:4.2f} "
                  f"[<= {GOALS['offline']}]  ({us:.2f} us/sample)")
            online, offline, vqf_rmse, _ = broad_scores(trial, runs, retimed=True)
            figures["broad_tilt_rmse_deg"][path.stem]["retimed"] = {"online": online, "offline": offline,
                                                                     "vqf_6d": vqf_rmse}
            print(f"  {'  reference re-timed to the IMU delay':34s} vqf6D {vqf_rmse:5.2f} | online {online:5.2f} ratio "
                  f"{online / vqf_rmse:4.2f} | offline {offline:5.2f} ratio {offline / vqf_rmse:4.2f}")
        run_us, run_wall_us, _ = run_command_cost_us(sorted(broad_dir.glob("07_*.hdf5"))[0])
    else:
        print(f"== BROAD skipped: {broad_dir} not found ==")
    if euroc_dir.is_dir():
        online, offline, vqf_rmse = euroc_tilt(config, euroc_dir)
        figures["euroc_tilt_rmse_deg"] = {"online": online, "offline": offline, "vqf_6d": vqf_rmse}
        print(f"== EuRoC V1_02 first 40 s, IMU-only, tilt RMSE deg: vqf6D {vqf_rmse:.2f} | online {online:.2f} "
              f"ratio {online / vqf_rmse:.2f} [<= {GOALS['euroc']}] | offline {offline:.2f} ratio "
              f"{offline / vqf_rmse:.2f} ==")
    else:
        print(f"== EuRoC skipped: {euroc_dir} not found ==")
    figures["fused_us"] = {}
    print("== cost of the filter, medians over runs ==")
    print("  fused: all the filter does but the visual update proper (propagation to the frames, accelerometer "
          "updates, checks, flags, estimates), wall time on replays (`fused_cost`), in a loop of the library's "
          "calls and between solver calls as in a pipeline; with the visual update in brackets")
    for name, label in (("handheld", "30 fps (handheld)"), ("bus", "15 fps (bus)")):
        runs = [r for r, _ in fused_us[name]]
        per_frame = float(np.median([n for _, n in fused_us[name]])) if runs else float("nan")
        figures["fused_us"][name] = {}
        for way in REPLAYS:
            without, with_visual = np.median([r[way] for r in runs], axis=0) if runs else (np.nan, np.nan)
            figures["fused_us"][name][way] = {"without_visual_update": float(without),
                                              "with_visual_update": float(with_visual)}
            goal = f"   [goal <= {GOALS['fused_us']:g}]" if name == "handheld" else ""
            print(f"  fused, 200 Hz IMU at {label + ',':18s} {REPLAY_LABELS[way]:21s} {without:.1f} us per IMU sample "
                  f"({with_visual:.1f}); {without * per_frame:.0f} us per frame ({with_visual * per_frame:.0f}){goal}")
    print("  IMU only: CPU time of the filter's thread (wall clock in brackets)")
    peers = {k: float(np.median(v)) if v else float("nan") for k, v in peer_us.items()}
    broad_us = float(np.median(imu_us["broad"])) if imu_us["broad"] else float("nan")
    print(f"  IMU only (BROAD, 286 Hz), library, one call: {broad_us:.2f} us per IMU sample [goal <= "
          f"{GOALS['batch_us']:g}]; vqf 6D {peers['vqf']:.2f} ({broad_us / peers['vqf']:.1f}x ours), "
          f"imufusion {peers['imufusion']:.2f} ({broad_us / peers['imufusion']:.1f}x ours)")
    print(f"  IMU only, whole `run` on a 184 s BROAD file (file sinks): {run_us:.2f} us per IMU sample "
          f"({run_wall_us:.2f}) [goal <= {GOALS['run_us']:g}]; vqf 6D {peers['vqf']:.2f}, imufusion "
          f"{peers['imufusion']:.2f} (library calls, no files)")
    print(f"  visual update incl. propagation to the frame: {np.median(vis_ms):.3f} ms "
          f"({np.median(vis_wall_ms):.3f})   [goal <= 0.3]")
    return figures
