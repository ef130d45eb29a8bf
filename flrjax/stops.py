"""Clean stops: the first Ctrl-C or SIGTERM ends a run after its chunk in flight, with a
checkpoint; a second one ends the process at once."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

from flrjax import checkpoint
from flrjax.config import TrainConfig

#: The signals that stop a run cleanly: Ctrl-C, and a cluster scheduler's notice before a kill.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Stopped(BaseException):
    """The run stopped on a signal of :data:`STOP_SIGNALS` after its chunk in flight, with a
    checkpoint of that chunk where it has an output directory. A ``BaseException``, as
    ``KeyboardInterrupt`` is, so that ``except Exception`` does not swallow the request."""

    def __init__(self, signum: int, chunks: int, cfg: TrainConfig):
        self.signum, self.chunks, self.out = signum, chunks, cfg.out
        where = (f"checkpoint in {checkpoint.ckpt_dir(cfg.out)}" if cfg.out else
                 "no checkpoint: the run has no output directory")
        super().__init__(
            f"{signal.Signals(signum).name}: stopped after chunk {chunks} of "
            f"{cfg.steps // cfg.steps_per_chunk} (env step {chunks * cfg.steps_per_chunk:,} "
            f"of {cfg.steps:,}); {where}")


@contextlib.contextmanager
def stop_on_signals() -> Iterator[list[int]]:
    """Within the block, the first signal of :data:`STOP_SIGNALS` is appended to the list
    yielded (the run stops after its chunk in flight, which cannot be interrupted) and puts
    back their default action, so that a second one ends the process at once. The previous
    handlers come back after the block. Only in the main thread, the one Python's signal
    handlers run in; elsewhere the list stays empty."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def request_stop(signum, frame):
        received.append(signum)
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_DFL)

    previous = {s: signal.signal(s, request_stop) for s in STOP_SIGNALS}
    try:
        yield received
    finally:
        for s, handler in previous.items():  # None: a handler not set from Python
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
