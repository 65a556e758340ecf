"""Solver speed benchmark: `python tools/bench_solver.py [--repeats N]` (same as `uareme-fusion bench solver`)."""

import argparse

from uareme_fusion.benchmarks import solver

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=100)
    solver.run(repeats=parser.parse_args().repeats)
