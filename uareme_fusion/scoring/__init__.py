"""Estimates scored against ground truth, pure maths in the manner of evo's core: per-frame attitude
errors, NEES and jumps (`metrics`), and their summaries (`statistics`). `pipeline` (a run's summary) and
`evaluation` (comparisons, benchmarks) both use them; they import nothing above `rotations`."""
