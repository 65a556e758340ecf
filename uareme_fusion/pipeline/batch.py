"""Many recordings at once: each source runs as `run` does, into `DIR/<name>/`, on a process pool or Ray.

    rows = run_batch(["a.bag", "flight.csv", "sim:room"], Path("out"), RunConfig(), workers=2)

- `batch_tasks` names each source's folder (`batch_names`) and, with `resume`, leaves out the sources
  whose `summary.json` says their run ended (`ENDED`); an earlier run that did not end is replaced.
- `run_task` is one source in a worker: `session.run_into_folder`, the code path of `run`, and
  whatever happens, one row (`BATCH_COLUMNS`): a bad source never stops the others.
- `run_batch` runs the tasks on a local process pool (`workers` processes, each loading the normal
  network once, at its first source) or, with `ray_address`, on `workers` Ray actors (`local`
  starts a Ray cluster on this machine), and writes `DIR/batch.csv` row by row as sources finish.
  On a cluster, DIR must be a folder every node sees: the workers write their outputs there.
- `wall_s` of a row: the seconds the source took in its worker (opening it and loading the model
  included); `fps`: the run's own (`RunStats.fps`).
"""

from __future__ import annotations

import csv
import io
import json
import multiprocessing
import os
import re
import signal
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError, UaremeError
from ..io.safe_files import RowFile
from .config import RunConfig

BATCH_COLUMNS = ("source", "status", "frames", "fps", "wall_s", "error")
"""Columns of `DIR/batch.csv`, one row per source; `status` is ok or failed."""
ENDED = ("end", "max_frames")
"""`summary.json` `stopped` values of a run that ended (ok, and skipped by `--resume`)."""


@dataclass(frozen=True)
class BatchTask:
    """One source of a batch: its spec, its output folder, whether an earlier result there is replaced."""

    source: str
    out_dir: str
    force: bool


def read_source_list(args: Iterable[str]) -> list[str]:
    """The sources given, with `@FILE` replaced by the lines of FILE (one source a line; blank lines and
    lines starting with # skipped)."""
    sources = []
    for arg in args:
        if not arg.startswith("@"):
            sources.append(arg)
            continue
        path = Path(arg[1:]).expanduser()
        try:
            lines = path.read_text(encoding="utf-8-sig").splitlines()
        except OSError as exc:
            raise InputError(f"{arg}: cannot read the list of sources ({exc.strerror or exc})") from None
        except UnicodeDecodeError:
            raise InputError(f"{arg}: the list of sources is not UTF-8 text") from None
        sources += [line.strip() for line in lines if line.strip() and not line.strip().startswith("#")]
    if not sources:
        raise InputError("batch: no sources given (name them, or @FILE with one a line)")
    return sources


def batch_names(sources: list[str]) -> list[str]:
    """A folder name per source: its file or folder name without the suffix (`sim:room` -> `sim_room`),
    with parent folder names put in front where two sources would share one (`V1_02_imu0_data`), then
    `_2`, `_3`... for a source given twice."""
    parts = [_name_parts(s) for s in sources]
    depth = [1] * len(sources)
    while True:
        names = ["_".join(p[-d:]) for p, d in zip(parts, depth)]
        clashing = [i for i, n in enumerate(names) if names.count(n) > 1 and depth[i] < len(parts[i])]
        if not clashing:
            break
        for i in clashing:
            depth[i] += 1
    seen: dict[str, int] = {}
    unique = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        unique.append(name if seen[name] == 1 else f"{name}_{seen[name]}")
    return unique


def _name_parts(source: str) -> list[str]:
    if ":" in source and not Path(source).exists():  # sim:room, webcam:0
        return [_safe(source)]
    path = Path(source).expanduser()
    parts = [p for p in path.resolve().parts if p != path.anchor]
    if parts:
        parts[-1] = Path(parts[-1]).stem if path.is_file() or path.suffix else parts[-1]
    return [_safe(p) for p in parts] or ["source"]


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_.") or "source"


def batch_tasks(sources: list[str], out_dir: Path, resume: bool, force: bool) -> tuple[list[BatchTask], list[dict]]:
    """(tasks to run, rows of sources skipped because their run ended), in the order given."""
    tasks, kept = [], []
    for source, name in zip(sources, batch_names(sources)):
        folder = Path(out_dir) / name
        summary = ended_summary(folder) if resume else None
        if summary is not None:
            kept.append(summary_row(source, summary, summary.get("wall_s", 0.0)))
        else:
            tasks.append(BatchTask(source, str(folder), force or resume))
    return tasks, kept


def ended_summary(folder: Path) -> dict | None:
    """The `summary.json` in `folder` when it says the run ended (`ENDED`); None otherwise."""
    try:
        summary = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) and summary.get("stopped") in ENDED else None


def summary_row(source: str, summary: dict, wall_s: float) -> dict:
    ok = summary.get("stopped") in ENDED and "summary_error" not in summary
    error = "" if ok else "; ".join(str(e) for e in (summary.get("error") or summary.get("stopped"),
                                                      summary.get("summary_error")) if e)
    return {"source": source, "status": "ok" if ok else "failed", "frames": int(summary.get("frames", 0)),
            "fps": float(summary.get("fps", 0.0)), "wall_s": float(wall_s), "error": error}


def failed_row(source: str, error: str, wall_s: float = 0.0) -> dict:
    return {"source": source, "status": "failed", "frames": 0, "fps": 0.0, "wall_s": float(wall_s), "error": error}


def run_task(task: BatchTask, cfg_data: dict) -> dict:
    """Run one source as `run` does (in a worker); its row, whatever happened."""
    from . import stop_signals
    from .session import run_into_folder

    t0 = time.perf_counter()
    try:  # Ctrl-C or SIGTERM stop the run as they stop `run`: summary.json written, a second one waits
        with stop_signals.handle_stop_signals():
            summary = run_into_folder(task.source, Path(task.out_dir), RunConfig.model_validate(cfg_data),
                                      task.force)
    except (UaremeError, OSError) as exc:
        return failed_row(task.source, str(exc), time.perf_counter() - t0)
    except Exception as exc:  # a bug met on one source: reported in its row, the others go on
        return failed_row(task.source, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0)
    return summary_row(task.source, summary, time.perf_counter() - t0)


class BatchCsv:
    """`DIR/batch.csv`, a header then one row per source as it finishes (streamed: a batch that stops
    keeps the rows of the sources done)."""

    def __init__(self, path: Path):
        self.file = RowFile(path)
        self.file.write_row(",".join(BATCH_COLUMNS) + "\n", counts=False)

    def write(self, row: dict) -> None:
        text = io.StringIO()
        values = {**row, "fps": f"{row['fps']:.3f}", "wall_s": f"{row['wall_s']:.3f}"}
        csv.writer(text, lineterminator="\n").writerow([values[c] for c in BATCH_COLUMNS])
        self.file.write_row(text.getvalue())

    def close(self) -> None:
        self.file.close()


def run_batch(sources: list[str], out_dir: Path, cfg: RunConfig, workers: int | None = None,
              ray_address: str | None = None, resume: bool = False, force: bool = False,
              on_row: Callable[[dict], None] | None = None) -> list[dict]:
    """Run every source into `out_dir/<name>/`; rows in the order of `sources` (see the module docstring).
    `on_row(row)` is called as each source finishes (and for each source `resume` skips)."""
    from .session import make_output_folder

    sources = list(dict.fromkeys(sources))  # a source given twice runs once
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    out = make_output_folder(out_dir)
    tasks, kept = batch_tasks(sources, out, resume, force)
    rows: dict[str, dict] = {}
    table = BatchCsv(out / "batch.csv")
    try:
        for row in kept:
            _finish(row, rows, table, on_row)
        if tasks:
            run_tasks = _run_on_ray if ray_address else _run_on_pool
            run_tasks(tasks, cfg.model_dump(mode="json"), workers, lambda row: _finish(row, rows, table, on_row),
                      **({"address": ray_address} if ray_address else {}))
    finally:
        table.close()
    return [rows[s] for s in dict.fromkeys(sources) if s in rows]


def _finish(row: dict, rows: dict, table: BatchCsv, on_row) -> None:
    rows[row["source"]] = row
    table.write(row)
    if on_row is not None:
        on_row(row)


def _run_on_pool(tasks: list[BatchTask], cfg_data: dict, workers: int, done: Callable[[dict], None]) -> None:
    """The tasks on `workers` local processes (forked from a server that imported this module once)."""
    context = multiprocessing.get_context("forkserver" if "forkserver" in multiprocessing.get_all_start_methods()
                                          else "spawn")
    if hasattr(context, "set_forkserver_preload"):
        context.set_forkserver_preload([__name__])
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=context) as pool:
        pending = {pool.submit(run_task, task, cfg_data): task for task in tasks}
        try:
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    task = pending.pop(future)
                    try:
                        done(future.result())
                    except Exception as exc:  # the worker process died (killed, out of memory)
                        done(failed_row(task.source, f"its worker process failed ({type(exc).__name__}: {exc})"))
        except KeyboardInterrupt:  # stop the running sources the way Ctrl-C stops a run: summary.json written
            for process in list(getattr(pool, "_processes", {}).values()):
                try:
                    os.kill(process.pid, signal.SIGINT)
                except OSError:
                    pass
            pool.shutdown(wait=True, cancel_futures=True)
            raise


class _RayWorker:
    """A Ray actor: one worker process, which loads the normal network once (at its first source) and
    writes each source's outputs into the shared output folder itself."""

    def run(self, task: BatchTask, cfg_data: dict) -> dict:
        return run_task(task, cfg_data)


def _run_on_ray(tasks: list[BatchTask], cfg_data: dict, workers: int, done: Callable[[dict], None],
                address: str) -> None:
    """The tasks on `workers` Ray actors; `address` 'local' starts a cluster on this machine, any other
    value is given to `ray.init` (`auto`, `HOST:6379`, `ray://HOST:10001`)."""
    try:
        import ray
    except ImportError:
        raise InputError("--ray needs the ray extra: pip install 'uareme-fusion[ray]'") from None
    local = address == "local"
    started_here = not ray.is_initialized()
    env = {"OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
    if local:  # this machine's workers import the very package the driver runs (a checkout too)
        package_parent = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join([package_parent, *filter(None, [os.environ.get("PYTHONPATH")])])
    if started_here:
        try:
            ray.init(**({"num_cpus": workers} if local else {"address": address}), include_dashboard=False,
                     log_to_driver=False, configure_logging=False, runtime_env={"env_vars": env})
        except Exception as exc:
            raise InputError(f"--ray {address}: cannot connect to a Ray cluster ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    try:
        actor_class = ray.remote(num_cpus=1)(_RayWorker)
        idle = [actor_class.remote() for _ in range(min(workers, len(tasks)))]
        queue, running = list(reversed(tasks)), {}
        while queue or running:
            while queue and idle:
                task, worker = queue.pop(), idle.pop()
                running[worker.run.remote(task, cfg_data)] = (task, worker)
            ready, _ = ray.wait(list(running), num_returns=1)
            task, worker = running.pop(ready[0])
            try:
                done(ray.get(ready[0]))
                idle.append(worker)
            except ray.exceptions.RayError as exc:  # the actor died: its source failed, a new one goes on
                done(failed_row(task.source, f"its Ray worker failed ({type(exc).__name__})"))
                idle.append(actor_class.remote())
    finally:
        if started_here:
            ray.shutdown()
