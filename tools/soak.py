"""Soak benchmark (issue 8): one simulated hour at 30 fps with a 400 Hz IMU through the full pipeline.

    python tools/soak.py                    # the hour (several minutes of wall time)
    python tools/soak.py --minutes 5        # quicker
    uareme-fusion bench soak --minutes 60   # the same from the command line

Prints RSS growth after the warm-up (goal < 5 MB), the pipeline's and backend's container sizes at
the start and end (no growth), tilt and ARE over the first and last minute, and the wall time.
"""

import argparse
import json

from uareme_fusion.benchmarks.soak import run

parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
parser.add_argument("--minutes", type=float, default=60.0, help="simulated stream length, min")
parser.add_argument("--normals-noise-deg", type=float, default=2.0, help="angular noise on the simulator's normals")
parser.add_argument("--preset", default="building", help="EKF preset (building, handheld, ...)")
parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
args = parser.parse_args()
result = run(seconds=args.minutes * 60.0, normals_noise_deg=args.normals_noise_deg, preset=args.preset)
if args.json:
    with open(args.json, "w") as fh:
        json.dump(result, fh, indent=2, default=float)
