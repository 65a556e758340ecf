"""`bench batch`: throughput of `uareme-fusion batch` on IMU-only sources with 1, 2 and N workers.

The sources are the real IMU-only recordings of the development data (the BROAD trials, EuRoC V1_02's
and V1_01 micro's IMU logs), each given `COPIES` times (links under other names) so that every worker
count has work to share. Each figure is one whole batch as a user runs it: the pool's start (its
processes importing the package and loading the EKF's kernels) included. Throughput is sources per
second; the scaling ratio is each count's throughput over one worker's (goal: 2 workers >= 1.6x on a
2-core machine). The load average is printed beside each figure: other programs on the machine
take cores from the workers, and the ratio means little when they do.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from ..errors import InputError
from ..pipeline import RunConfig
from ..pipeline.batch import run_batch

COPIES = 12
"""How many times each real IMU-only recording is given to the batch."""
SCALING_GOAL = 1.6
"""2 workers' throughput over one worker's, on a 2-core machine."""


def imu_only_sources(data_dir: Path) -> list[Path]:
    """The real IMU-only recordings under the development data folder `data_dir`."""
    found = sorted((data_dir / "broad_subset").glob("*.hdf5"))
    found += [p for p in (data_dir / "euroc_v1_02_first40s" / "mav0" / "imu0" / "data.csv",
                          data_dir / "euroc_v1_01_micro" / "mav0" / "imu0" / "data.csv") if p.is_file()]
    if not found:
        raise InputError(f"--data {data_dir}: no broad_subset/*.hdf5 or EuRoC imu0/data.csv there (see "
                         "shared/data/README.md)")
    return found


def run(data_dir: Path, copies: int = COPIES) -> dict:
    """Print and return the throughput (sources/s) and scaling of 1, 2 and N workers (N = cores)."""
    recordings = imu_only_sources(Path(data_dir))
    cores = os.cpu_count() or 1
    counts = sorted({1, 2, cores})
    figures = {"cores": cores, "sources": len(recordings) * copies, "recordings": [str(p) for p in recordings],
               "workers": {}}
    print(f"batch of {figures['sources']} IMU-only sources ({len(recordings)} real recordings x {copies}), "
          f"{cores} cores")
    print(f"{'workers':>7s} {'wall s':>8s} {'sources/s':>10s} {'scaling':>8s} {'failed':>6s}  "
          "load (1 min) before/after")
    with tempfile.TemporaryDirectory() as tmp:
        links = []
        for copy in range(copies):
            for i, path in enumerate(recordings):
                link = Path(tmp) / "in" / f"c{copy}_r{i}" / path.name
                link.parent.mkdir(parents=True)
                link.symlink_to(path.resolve())
                links.append(str(link))
        for workers in counts:
            load_before = os.getloadavg()[0]
            t0 = time.perf_counter()
            rows = run_batch(links, Path(tmp) / f"out{workers}", RunConfig(), workers=workers)
            wall_s = time.perf_counter() - t0
            failed = sum(r["status"] != "ok" for r in rows)
            entry = {"wall_s": wall_s, "sources_per_s": len(rows) / wall_s, "failed": failed,
                     "load_before": load_before, "load_after": os.getloadavg()[0]}
            entry["scaling"] = entry["sources_per_s"] / figures["workers"][1]["sources_per_s"] if workers > 1 else 1.0
            figures["workers"][workers] = entry
            print(f"{workers:7d} {wall_s:8.2f} {entry['sources_per_s']:10.2f} {entry['scaling']:7.2f}x {failed:6d}  "
                  f"{load_before:.1f} / {entry['load_after']:.1f}")
    if 2 in figures["workers"]:
        ratio = figures["workers"][2]["scaling"]
        print(f"2 workers: {ratio:.2f}x one worker (goal >= {SCALING_GOAL}x on a 2-core machine: "
              f"{'met' if ratio >= SCALING_GOAL else 'not met'}); a load above {cores} means other programs "
              "shared the cores")
    return figures
