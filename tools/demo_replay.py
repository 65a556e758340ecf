"""The demo's rendered scenes (SYNTHETIC), solved once into a cache, then the EKF replayed with overrides.

`uareme-fusion demo` runs a rendered room (handheld preset) and a bus (vehicle preset) through the whole
pipeline. This tool keeps the pipeline's per-frame visual rotations with the IMU and the ground truth
(`--cache`, built on the first call, about a minute), then replays `single`, the IMU alone and `mekf` with
`--mekf KEY=VALUE` overrides in seconds. It prints the means and one figure per second (tilt and ARE, deg),
and with `--bias` the mekf's gyro bias (IMU frame, deg/s) and attitude std at the end of each second.
This is how the room's wrong gyro bias was found (MekfConfig.gyro_bias_visual_correlation_s).

Usage:
  python tools/demo_replay.py --scene room --cache /tmp/demo_room.pkl [--mekf gyro_bias_visual_correlation_s=0] [--bias]
"""

from __future__ import annotations

import argparse
import pickle
from pathlib import Path

import numpy as np


def build(scene: str, cache: Path) -> None:
    from uareme_fusion.demo import scene_sequence

    seq, _, _ = scene_sequence(scene)  # as `uareme-fusion demo` renders and solves it
    with open(cache, "wb") as f:
        pickle.dump(seq, f)


def replay(scene: str, cache: Path, overrides: dict, bias: bool) -> None:
    from uareme_fusion.backends.factory import make_backend
    from uareme_fusion.backends.mekf import MekfMode
    from uareme_fusion.demo import DEMO_SCENES
    from uareme_fusion.evaluation.compare import errors_over_time, run_backend

    with open(cache, "rb") as f:
        seq = pickle.load(f)
    preset = DEMO_SCENES[scene][0]
    second = np.floor(seq.t_frame_s - seq.t_frame_s[0]).astype(int)
    backends = {"single": make_backend("single"),
                "imu only": make_backend("mekf", mekf_preset=preset, overrides={"mode": MekfMode.IMU_ONLY}),
                "mekf": make_backend("mekf", mekf_preset=preset, overrides=overrides)}
    for name, backend in backends.items():
        run = run_backend(backend, seq)
        err = errors_over_time(run, seq.R_wc_true)
        ok = err["initialised"]
        for key in ("tilt_deg", "are_deg"):
            per_second = [np.mean(err[key][ok & (second == s)]) for s in range(second.max() + 1)]
            print(f"{name:8s} {key[:-4]:4s} mean {np.mean(err[key][ok]):5.2f} | per s "
                  + " ".join(f"{x:.1f}" for x in per_second))
        if bias and name == "mekf":
            for s in range(second.max() + 1):
                e = run.estimates[np.flatnonzero(second == s)[-1]]
                print(f"  s {s:2d} bias deg/s {np.round(np.degrees(e.gyro_bias_rad_s), 2)} "
                      f"std deg {np.round(np.degrees(np.sqrt(np.diag(e.cov))), 2)}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", choices=("room", "bus"), default="room")
    p.add_argument("--cache", type=Path, required=True, help="built on the first call")
    p.add_argument("--mekf", nargs="*", default=[], help="MekfConfig overrides KEY=VALUE")
    p.add_argument("--bias", action="store_true", help="the mekf's gyro bias and std per second")
    args = p.parse_args()
    import yaml

    overrides = {k: yaml.safe_load(v) for k, v in (kv.split("=", 1) for kv in args.mekf)}
    if not args.cache.exists():
        build(args.scene, args.cache)
    replay(args.scene, args.cache, overrides, args.bias)


if __name__ == "__main__":
    main()
