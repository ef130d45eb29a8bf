"""``python phases.py ARGS`` runs ``python -m flrjax.train ARGS`` with phase marks: seconds
since ``$LAUNCH_T`` (the shell's launch time) appended to the file ``$PHASES`` as each phase
starts and ends. ``WARM=1``: ``jax.devices()`` in a thread right after JAX's import; ``WARM=2``: a
first tiny program there. flrjax's command line starts one itself since 0332c57, which this
script, running the trainer through runpy, triggers only with ``CLI=1`` (``sys.argv`` and
``sys.orig_argv`` then read as ``python -m flrjax.train ARGS`` while flrjax imports)."""
import os
import runpy
import sys
import threading
import time

T0 = float(os.environ["LAUNCH_T"])
LOG = open(os.environ["PHASES"], "a")  # noqa: SIM115 (open for the whole run)


def mark(name: str) -> None:
    LOG.write(f"{time.time() - T0:8.2f} {name}\n")
    LOG.flush()


mark("python up")
import jax  # noqa: E402

mark("import jax")


def _backend() -> None:
    jax.devices()
    mark("backend up (thread)")


def _first_program() -> None:
    jax.jit(lambda x: x + 1)(jax.numpy.zeros(1)).block_until_ready()
    mark("first program (thread)")


if os.environ.get("WARM") in ("1", "2"):
    target = _backend if os.environ["WARM"] == "1" else _first_program
    threading.Thread(target=target, daemon=True).start()

ARGS = sys.argv[1:]
if os.environ.get("CLI") == "1":
    sys.argv = ["-m", *ARGS]
    sys.orig_argv = [sys.executable, "-m", "flrjax.train", *ARGS]

import flrjax.checkpoint as ck  # noqa: E402
import flrjax.cli as cli  # noqa: E402
import flrjax.config as config  # noqa: E402
import flrjax.metrics_io as mio  # noqa: E402
import flrjax.runner as runner  # noqa: E402
import flrjax.train  # noqa: E402, F401

mark("import flrjax")


def wrap(mod, name: str, every: bool) -> None:
    """Mark ``mod.name``'s first call (every call with ``every``)."""
    f, n = getattr(mod, name), [0]

    def g(*a, **k):
        n[0] += 1
        if every or n[0] == 1:
            mark(f"{name} start #{n[0]}")
        r = f(*a, **k)
        if every or n[0] == 1:
            mark(f"{name} end #{n[0]}")
        return r

    setattr(mod, name, g)


for mod, name, every in [
        (cli, "parse_cli", 0), (mio, "resolved_settings", 1), (config, "make_env", 1),
        (runner, "check_memory", 0), (runner, "init_carry", 0), (runner, "carry_shapes", 0),
        (ck, "restore", 0), (ck, "_read", 1), (ck, "_checksum", 1), (mio, "append_rows", 0),
        (mio, "prepare_out", 0), (ck, "_read_host", 1), (ck, "_restore", 1),
        (ck, "read_ahead", 1)]:
    if hasattr(mod, name):  # the commit before the read-ahead lacks some
        wrap(mod, name, every)


class First:
    """The chunk program, its first call marked."""

    def __init__(self, f):
        self.f, self.n = f, 0

    def __getattr__(self, a):
        return getattr(self.f, a)

    def __call__(self, *a):
        self.n += 1
        if self.n == 1:
            mark("first chunk call")
        r = self.f(*a)
        if self.n == 1:
            jax.block_until_ready(r)
            mark("first chunk done")
        return r


_build = runner.build


def build(cfg):
    mark("build start")
    init, chunk, ev = _build(cfg)
    mark("build end")
    return init, First(chunk), ev


runner.build = build
sys.argv = ["flrjax.train", *ARGS]
try:
    runpy.run_module("flrjax.train", run_name="__main__")
finally:
    mark("exit")
