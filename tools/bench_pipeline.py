"""End-to-end pipeline benchmark (issue 7): fps and per-stage ms at 640x480, memory over a long stream.

    python tools/bench_pipeline.py                       # 10 s of frames, 10-minute memory stream
    python tools/bench_pipeline.py --memory-minutes 1    # quicker
"""

import argparse

from uareme_fusion.benchmarks.pipeline import run

parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
parser.add_argument("--seconds", type=float, default=10.0, help="length of the timed room walk, s")
parser.add_argument("--memory-minutes", type=float, default=10.0, help="length of the memory stream, min (0: skip)")
parser.add_argument("--normals", default="learned", help="learned (default) or a model file")
args = parser.parse_args()
run(args.seconds, args.memory_minutes, args.normals)
