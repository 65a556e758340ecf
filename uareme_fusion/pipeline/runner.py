"""The streaming loop: each frame's normals, visual rotation and estimate, handed to the sinks.

Memory is bounded: nothing per frame is kept here (sinks write and forget; timings are running
sums). A source that fails mid-stream, input found bad mid-stream (an `InputError`: e.g. fewer normal
maps than frames) or Ctrl-C ends the run cleanly: the sinks are closed, so everything written so far
stays complete and valid, and `RunStats.stopped` says why it ended.

An IMU-only source (no frames: one estimate per IMU batch) goes in bulk: `IMU_ONLY_BULK_BATCHES`
batches at a time to `Backend.process_imu_segments`, their estimates (`types.Estimates`) to the
sinks' `write_many` together (signals wait until all are written and counted); a sink without
`write_many` gets them one `FrameResult` at a time, as with frames.
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from ..backends.base import Backend, SteadyPart
from ..drivers.base import Source
from ..errors import InputError, OutputError, SourceError
from ..solver.cues import pool_before_run, solve_frame
from ..types import Estimates, Frame, FrameResult, ImuBatch, NormalMap, Status, VisualRotation
from . import stop_signals

STAGES = ("source", "normals", "solver", "backend", "sinks")
IMU_ONLY_BULK_BATCHES = 256
"""Batches of an IMU-only source handled together (about 8.5 s at 30 estimates per second): the
sinks write and flush their rows once per this many."""


class StageTimes:
    """Running sums of the seconds spent in each stage (bounded memory)."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)

    def add(self, stage: str, seconds: float) -> None:
        self.seconds[stage] += seconds
        self.calls[stage] += 1

    def mean_ms(self, per: int) -> dict[str, float]:
        """Milliseconds per output (frame) in each stage and in total."""
        per = max(per, 1)
        out = {s: 1e3 * self.seconds[s] / per for s in STAGES if s in self.seconds}
        out["total"] = sum(out.values())
        return out


@dataclass
class RunStats:
    """Counts and timings of one run; `stopped` is end, max_frames, interrupted (Ctrl-C, SIGTERM or
    SIGHUP: `signal` holds its number), source_error, input_error or output_error (a file that could
    not be written; `error` holds the message of the last four)."""

    source: str = ""
    normals: str = ""
    backend: str = ""
    frames: int = 0
    estimates: int = 0
    frames_without_visual: int = 0
    frames_without_depth: int = 0
    """Frames that had no depth map while depth normals were asked for (flagged DEPTH_MISSING)."""
    imu_samples: int = 0
    status_counts: Counter = field(default_factory=Counter)
    times: StageTimes = field(default_factory=StageTimes)
    wall_s: float = 0.0
    warm_up_s: float = 0.0
    """Of `wall_s`, what ran before the first event: a recording's K pooled before the run
    (`cues.pool_before_run`) and the backend's loading (`Backend.warm_up`)."""
    stopped: str = "end"
    error: str | None = None
    signal: int | None = None
    started_s: float = 0.0
    """`time.perf_counter()` when the run began (see `fps`)."""

    @property
    def fps(self) -> float:
        """Estimates per second of the run's wall time (warm-up included): the one definition of a run's
        speed, in summary.json, the final table and the progress bar (so far, while it runs)."""
        elapsed_s = self.wall_s if self.wall_s > 0 else time.perf_counter() - self.started_s
        return self.estimates / elapsed_s if self.started_s > 0 and elapsed_s > 0 else 0.0

    def as_dict(self) -> dict:
        return {"source": self.source, "normals": self.normals, "backend": self.backend,
                "frames": self.frames, "estimates": self.estimates,
                "frames_without_visual": self.frames_without_visual,
                "frames_without_depth": self.frames_without_depth, "imu_samples": self.imu_samples,
                "status_counts": dict(sorted(self.status_counts.items())),
                "timing_ms": self.times.mean_ms(self.estimates),
                "fps": self.fps,
                "wall_s": self.wall_s, "warm_up_s": self.warm_up_s, "stopped": self.stopped, "error": self.error,
                **({"signal": self.signal} if self.signal is not None else {})}

    def interrupted(self, exc: BaseException | None = None, signum: int | None = None) -> None:
        if signum is not None:
            exc = stop_signals.StopRequested(signum)
        self.stopped, self.error = "interrupted", stop_signals.describe(exc)
        self.signal = getattr(exc, "signum", 2)


_STATUS_BITS = tuple((flag.name, int(flag)) for flag in Status if flag)
"""Each status flag's name and bit, as plain ints (enum.Flag operations cost about a microsecond each)."""


class Pipeline:
    """normals -> solver -> backend -> sinks, one event at a time.

    `normals` has `estimate_frame(Frame) -> NormalMap`; each sink has `write(FrameResult)` and
    `close()`. The solver starts from the backend's predicted `R_cm` (or the last visual rotation),
    and searches globally on the first frame.
    """

    def __init__(self, normals, backend: Backend, sinks: Iterable = (), cues=None):
        self.normals, self.backend, self.sinks = normals, backend, list(sinks)
        self.cues = cues
        """A `cues.CueSolver` (normals and/or lines); None: the normals-only solver."""
        self._R_cm_prev = None
        self.steady = SteadyPart()
        """The estimates' steady part (`backends.base.SteadyPart`)."""
        self.stats = RunStats(backend=backend.name)
        self.accelerometer = None
        """An `interleave.AccelerometerFeed` of an accelerometer without gyro, fed up to each frame; None: none."""

    def process_imu(self, batch: ImuBatch) -> None:
        t0 = time.perf_counter()
        if len(batch):
            self.backend.process_imu(batch.t_s, batch.gyro_rad_s, batch.accel_m_s2)
        self.stats.imu_samples += len(batch)
        self.stats.times.add("backend", time.perf_counter() - t0)

    def visual_rotation(self, normal_map: NormalMap | None, t_s: float, frame: Frame | None = None) -> VisualRotation | None:
        """The solver's rotation for one frame, None when it has no usable cue (no valid normals, no lines)."""
        R_init = self.backend.predicted_R_cm(t_s)
        visual = solve_frame(self.cues, frame, normal_map, R_init if R_init is not None else self._R_cm_prev,
                             image_motion=self.backend.uses_image_motion)
        if visual is None:
            return None
        self._R_cm_prev = visual.R_cm
        return visual

    def process_frame(self, frame: Frame) -> FrameResult:
        times = self.stats.times
        t0 = time.perf_counter()
        normal_map = self.normals.estimate_frame(frame) if self.normals is not None else None
        if self.accelerometer is not None:
            self.backend.process_accel(*self.accelerometer.until(frame.t_s + self.backend.accelerometer_lookahead_s))
        t1 = time.perf_counter()
        visual = self.visual_rotation(normal_map, frame.t_s, frame)
        t2 = time.perf_counter()
        estimate = self.steady(self.backend.process_frame(frame.t_s, visual), visual)
        if normal_map is None and frame.depth is None and getattr(self.normals, "needs_depth", False):
            estimate = dataclasses.replace(estimate, status=estimate.status | Status.DEPTH_MISSING)
            self.stats.frames_without_depth += 1
        if visual is not None and (visual.jump_deg > 0 or visual.reason):
            flags = (Status.VISUAL_JUMP if visual.jump_deg > 0 else Status.OK) | (
                Status.VISUAL_NO_EVIDENCE if visual.reason else Status.OK)
            estimate = dataclasses.replace(estimate, status=estimate.status | flags)
        t3 = time.perf_counter()
        times.add("normals", t1 - t0)
        times.add("solver", t2 - t1)
        times.add("backend", t3 - t2)
        self.stats.frames += 1
        self.stats.frames_without_visual += visual is None
        focal = getattr(self.cues, "focal", None)
        K = focal.K if focal is not None and focal.source != "assumed" else frame.K
        return self._emit(FrameResult(frame.t_s, estimate, frame, normal_map, visual, K))

    def _emit(self, result: FrameResult) -> FrameResult:
        self._deliver(lambda sink: sink.write(result), np.array([int(result.estimate.status)]))
        return result

    def _deliver(self, write: Callable, statuses: np.ndarray) -> None:
        """`write(sink)` for every sink, then count the results (their status bits `statuses`); a
        stop signal waits until every sink has them. A sink refusing them (bad input, full disk)
        makes the sinks already written take them back, so the files hold whole results only."""
        t0 = time.perf_counter()
        with stop_signals.writing():
            for k, sink in enumerate(self.sinks):
                try:
                    write(sink)
                except (InputError, OutputError):
                    for written in self.sinks[:k]:
                        getattr(written, "undo_last", lambda: None)()
                    raise
            self.stats.times.add("sinks", time.perf_counter() - t0)
            self.stats.estimates += len(statuses)
            present = int(np.bitwise_or.reduce(statuses)) if len(statuses) else 0
            for name, bit in _STATUS_BITS:
                if bit & present:  # count only the bits seen (per frame, a hot path)
                    self.stats.status_counts[name] += int(np.count_nonzero(statuses & bit))

    def run(self, source: Source, max_frames: int | None = None,
            on_result: Callable[[FrameResult, RunStats], None] | None = None) -> RunStats:
        """Consume `source` to its end (or `max_frames`), then close the sinks; never raises for a
        source failure, bad input met mid-stream or Ctrl-C: `stats.stopped` and `stats.error` say
        what happened."""
        stats = self.stats
        stats.source = source.info.name
        imu_only = not source.info.has_frames
        start = stats.started_s = time.perf_counter()
        events = iter(source.events())
        try:
            # Before the first event: a recording's K from frames spread over it, and the backend's loading
            # (a live stream's first frames do not wait for it).
            pool_before_run(self.cues, source, max_frames)
            self.backend.warm_up(source.info.has_imu, source.info.has_frames)
            stats.warm_up_s = time.perf_counter() - start
            if imu_only:
                self._run_imu_only(events, max_frames, on_result)
            else:
                self._run_events(events, max_frames, on_result)
        except SourceError as exc:
            stats.stopped, stats.error = "source_error", str(exc)
        except InputError as exc:
            stats.stopped, stats.error = "input_error", str(exc)
        except OutputError as exc:
            stats.stopped, stats.error = "output_error", str(exc)
        except KeyboardInterrupt as exc:
            stats.interrupted(exc)
        finally:
            stats.wall_s = time.perf_counter() - start
            stats.normals = getattr(self.normals, "name", "") if self.normals is not None else ""
            with stop_signals.writing(deliver=False):  # files are finished even when a signal comes now
                self.close()
            signum = stop_signals.take_pending()
            if signum is not None and stats.stopped != "interrupted":
                stats.interrupted(signum=signum)
        return stats

    def _run_events(self, events, max_frames: int | None, on_result) -> None:
        """Frames and IMU batches one at a time: an estimate per frame."""
        stats = self.stats
        while max_frames is None or stats.estimates < max_frames:
            t0 = time.perf_counter()
            event = next(events, None)
            stats.times.add("source", time.perf_counter() - t0)
            if event is None:
                return
            if isinstance(event, ImuBatch):
                self.process_imu(event)
            else:
                result = self.process_frame(event)
                if on_result is not None:
                    on_result(result, stats)
        stats.stopped = "max_frames"

    def _run_imu_only(self, events, max_frames: int | None, on_result) -> None:
        """An IMU-only source in bulk: up to `IMU_ONLY_BULK_BATCHES` batches at a time go to the
        backend in one call (`Backend.process_imu_segments`: one estimate per batch, at its last
        sample), and their estimates to the sinks together."""
        stats = self.stats
        while max_frames is None or stats.estimates < max_frames:
            wanted = IMU_ONLY_BULK_BATCHES if max_frames is None else min(IMU_ONLY_BULK_BATCHES,
                                                                          max_frames - stats.estimates)
            t0 = time.perf_counter()
            batches, ended = [], False
            while len(batches) < wanted:
                event = next(events, None)
                if event is None:
                    ended = True
                    break
                if len(event):
                    batches.append(event)
            stats.times.add("source", time.perf_counter() - t0)
            if batches:
                self._emit_many(self._estimates_of(batches), on_result)
            if ended:
                return
        stats.stopped = "max_frames"

    def _estimates_of(self, batches: list[ImuBatch]) -> Estimates:
        t0 = time.perf_counter()
        rows = np.concatenate([b.rows for b in batches])
        ends = np.cumsum([b.rows.shape[0] for b in batches])
        t_s = rows[:, 0]
        estimates = self.backend.process_imu_segments(t_s, rows[:, 1:4], rows[:, 4:7], ends)
        self.stats.imu_samples += t_s.size
        self.stats.times.add("backend", time.perf_counter() - t0)
        # No camera: "no visual rotation" is no news, so the flag is dropped.
        return estimates.without(Status.VISUAL_MISSING)

    def _emit_many(self, estimates: Estimates, on_result) -> None:
        """Every sink gets the estimates (`write_many`, or one `FrameResult` at a time when a sink
        has no `write_many`); a stop signal waits until they are written and counted."""
        if not all(hasattr(sink, "write_many") for sink in self.sinks):
            for k in range(len(estimates)):
                result = self._emit(FrameResult(float(estimates.t_s[k]), estimates[k]))
                if on_result is not None:
                    on_result(result, self.stats)
            return
        self._deliver(lambda sink: sink.write_many(estimates), np.asarray(estimates.status))
        if on_result is not None:
            on_result(FrameResult(float(estimates.t_s[-1]), estimates[len(estimates) - 1]), self.stats)

    def close(self) -> None:
        """Close every sink (an mp4 gets its index); a sink that cannot finish its file ends the run as
        output_error, and the others are still closed."""
        for sink in self.sinks:
            try:
                sink.close()
            except OutputError as exc:
                if self.stats.stopped == "output_error":
                    if str(exc) not in self.stats.error:  # the same refusal met again while closing
                        self.stats.error = f"{self.stats.error}; {exc}"
                else:
                    self.stats.stopped, self.stats.error = "output_error", str(exc)
