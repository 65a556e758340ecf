"""Ctrl-C, SIGTERM and SIGHUP stop a run the same clean way, never in the middle of writing a result.

    with handle_stop_signals():          # the CLI, around a whole command
        ...
        with writing():                  # the pipeline, around handing one result to the sinks
            for sink in sinks: sink.write(result)

`handle_stop_signals` makes SIGINT, SIGTERM and SIGHUP raise `StopRequested` (a `KeyboardInterrupt`,
so every clean-up path written for Ctrl-C runs) with the signal's number; the process then exits
with 128 + that number. Inside `writing()` the signal is held until the block ends, so a result is
written to every sink or to none, and the counts in summary.json match what the files hold. Once
a stop has been raised, further signals are only recorded: the clean-up (closing files, writing
summary.json) is not cut short by a second Ctrl-C. Without `handle_stop_signals` (library use),
`writing()` does nothing and Python's own Ctrl-C behaviour applies.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class StopRequested(KeyboardInterrupt):
    """A stop asked for by a signal; `signum` is its number (2 for Ctrl-C)."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def description(self) -> str:
        if self.signum == signal.SIGINT:
            return "interrupted by the user (Ctrl-C)"
        return f"stopped by {signal.Signals(self.signum).name}"


def exit_code(exc: BaseException) -> int:
    """128 + the signal number (130 for Ctrl-C), the shell's convention."""
    return 128 + getattr(exc, "signum", signal.SIGINT)


def describe(exc: BaseException) -> str:
    return exc.description if isinstance(exc, StopRequested) else "interrupted by the user (Ctrl-C)"


class _State:
    installed = False
    held = 0
    pending: int | None = None
    raised = False


_state = _State()


def _on_signal(signum, frame) -> None:
    if _state.raised:
        return  # already stopping: let the clean-up finish
    if _state.held:
        _state.pending = _state.pending or signum
        return
    _state.raised = True
    raise StopRequested(signum)


@contextmanager
def handle_stop_signals():
    """Install the handlers (main thread only) for the duration of the block; restore the old ones."""
    if threading.current_thread() is not threading.main_thread() or _state.installed:
        yield
        return
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    _state.installed, _state.held, _state.pending, _state.raised = True, 0, None, False
    for s in STOP_SIGNALS:
        signal.signal(s, _on_signal)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _state.installed = False


@contextmanager
def writing(deliver: bool = True):
    """Hold stop signals until the block ends; then raise the held one when `deliver` (and the block
    did not fail: a failure propagates, the signal stays pending for `take_pending`)."""
    _state.held += 1
    try:
        yield
    except BaseException:
        _state.held -= 1
        raise
    _state.held -= 1
    if deliver and not _state.held and _state.pending is not None and not _state.raised:
        raise StopRequested(take_pending())


def take_pending() -> int | None:
    """The held signal's number (None when there is none); it counts as raised from now on."""
    signum, _state.pending = _state.pending, None
    if signum is not None:
        _state.raised = True
    return signum
