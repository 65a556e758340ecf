"""Benchmarks that print absolute figures and ratios (`uareme-fusion bench`, `tools/bench_*.py`)."""
