"""Run a grid's programs side by side: one per GPU (or group of GPUs) of this host, or as jobs
through submitit (https://github.com/facebookincubator/submitit): on SLURM, or its local
executor on this host.

A program is a command line (``run_grid.py`` with one variant); the caller leaves out the
finished ones. Each program's output goes to its own log; a failed program is reported in one
line and the others go on. Ctrl-C, or SIGTERM to the process group (as a scheduler sends it),
starts no more programs: the running ones stop after their chunk, checkpointed, on the signal
they get themselves (forwarding it would be a second signal, which ends a run at once); SLURM
jobs are cancelled, which signals them the same way.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from itertools import takewhile

import jax

#: SLURM time a job gets beyond its ``--time-limit``: starting Python and JAX, and the last
#: checkpoint after the limit's clean stop, all before submitit's notice ahead of the end.
SLURM_MARGIN_S = 300

#: submitit's local executor ends a job after ``timeout_min`` (2 by default): the limit given to
#: a program run without ``--time-limit``, which should never end it.
LOCAL_TIMEOUT_MIN = 60 * 24 * 365

#: Seconds between looks at the running programs on this host, and at SLURM jobs (whose
#: result files submitit looks for on a shared file system, and whose states it asks sacct).
POLL_S = 0.2
SLURM_POLL_S = 10.0

#: (program name, seconds left of the time limit or None) -> its command line
Command = Callable[[str, "float | None"], list[str]]

#: JAX's switch for taking most of a GPU's memory when it first puts an array there.
PREALLOCATE = "XLA_PYTHON_CLIENT_PREALLOCATE"


class Failed(SystemExit):
    """Some programs failed (each reported above); the others ran."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The placement flags, shared by ``run_grid.py`` and ``figures.py``."""
    g = p.add_argument_group("placement", "where the programs run (see the end)")
    g.add_argument("--gpus", default=None, metavar="0,1,...",
                   help="GPUs to place programs on (default: CUDA_VISIBLE_DEVICES, else all "
                        "that nvidia-smi -L lists)")
    g.add_argument("--gpus-per-program", type=int, default=1, metavar="N",
                   help="GPUs each program gets, on this host or per SLURM job (default 1)")
    g.add_argument("--submitit", choices=("slurm", "local"), default=None,
                   help="submit each program as a job through submitit (pip install "
                        "'flrjax[cluster]'): slurm (each job's time is --time-limit + "
                        f"{SLURM_MARGIN_S // 60} min), or local (its local executor, on "
                        "this host's GPUs as above)")
    g.add_argument("--slurm-partition", default=None, metavar="NAME",
                   help="SLURM partition of the jobs")
    g.add_argument("--slurm-param", action="append", default=[], metavar="KEY=VALUE",
                   help="another sbatch option for every job, e.g. account=proj or "
                        "cpus-per-task=8 (repeatable)")


def forward(args: argparse.Namespace) -> list[str]:
    """The placement flags of ``args`` as a command line again (``figures.py`` to
    ``run_grid.py``)."""
    return [*(["--gpus", args.gpus] if args.gpus is not None else []),
            "--gpus-per-program", str(args.gpus_per_program),
            *(["--submitit", args.submitit] if args.submitit else []),
            *(["--slurm-partition", args.slurm_partition] if args.slurm_partition else []),
            *(a for kv in args.slurm_param for a in ("--slurm-param", kv))]


def start_jax_without_preallocating() -> None:
    """Start JAX in this process, which only parses configs and places programs, without
    preallocating GPU memory: parsing puts a few small arrays on the first GPU, and the
    program placed there would lack the memory JAX takes for them. The environment is put
    back afterwards, so the programs (on this host or through submitit) preallocate as usual."""
    old = os.environ.get(PREALLOCATE)
    os.environ[PREALLOCATE] = "false"
    try:
        jax.devices()
    finally:
        if old is None:
            del os.environ[PREALLOCATE]
        else:
            os.environ[PREALLOCATE] = old


def visible_gpus(gpus: str | None = None) -> list[str]:
    """The GPUs to place programs on: ``gpus`` (``--gpus 0,1``), else CUDA_VISIBLE_DEVICES, else
    every GPU ``nvidia-smi -L`` lists (none where it is missing or fails). A list ends where
    CUDA's does, at the first empty or negative entry (``-1`` hides every GPU)."""
    spec = gpus if gpus is not None else os.environ.get("CUDA_VISIBLE_DEVICES")
    if spec is not None:
        return list(takewhile(lambda g: g and not g.startswith("-"),
                              (g.strip() for g in spec.split(","))))
    try:
        listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True,
                                check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    return [str(i) for i, _ in enumerate(ln for ln in listed.splitlines()
                                         if ln.startswith("GPU "))]


def slots(args: argparse.Namespace) -> list[str | None] | None:
    """Where programs run side by side: each slot a CUDA_VISIBLE_DEVICES value (None: this
    host as it is, no GPU), as many slots as programs at a time; None where they run one after
    the other in this process (no ``--gpus`` and no more GPUs than one program takes)."""
    gpus, per = visible_gpus(args.gpus), args.gpus_per_program
    if args.gpus is not None and not gpus:
        raise SystemExit(f"run_grid: --gpus {args.gpus!r} names no GPU")
    if per < 1 or (gpus and per > len(gpus)):
        raise SystemExit(f"run_grid: --gpus-per-program {per} of {len(gpus)} GPUs")
    if args.submitit is None and args.gpus is None and len(gpus) <= per:
        return None
    return [",".join(gpus[i:i + per]) for i in range(0, len(gpus) - per + 1, per)] or [None]


def _last_line(text: str) -> str:
    """The last non-empty line of ``text`` (progress bars' carriage returns end lines too)."""
    lines = [ln.strip() for ln in text.replace("\r", "\n").splitlines() if ln.strip()]
    return lines[-1] if lines else "(no output)"


class _Process:
    """A program as a child process of this one, on the GPUs of its slot."""

    def __init__(self, argv: list[str], slot: str | None, log: str):
        self.where, self.log = (f"GPU {slot}" if slot else "this host"), log
        env = dict(os.environ) if slot is None else {**os.environ, "CUDA_VISIBLE_DEVICES": slot}
        os.makedirs(os.path.dirname(log), exist_ok=True)
        with open(log, "a") as f:  # a rerun that resumes the run appends to its log
            self.proc = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, env=env)

    def ended(self) -> bool:
        return self.proc.poll() is not None

    def outcome(self) -> tuple[bool, str]:
        """Whether it succeeded, and its last line (its summary, or why it failed)."""
        with open(self.log) as f:
            last = _last_line(f.read())
        rc = self.proc.returncode
        return rc == 0, last if rc == 0 else f"exit {rc}: {last}"

    def stop(self) -> None:
        """Nothing: the program got the same signal as this process."""


class _Job:
    """A program as a submitit job (its command run by submitit's CommandFunction)."""

    def __init__(self, job, cancel: bool):
        self.job, self.cancel = job, cancel
        self.where, self.log = f"job {job.job_id}", str(job.paths.stdout)

    def ended(self) -> bool:
        return self.job.done()

    def outcome(self) -> tuple[bool, str]:
        error = self.job.exception()
        if error is None:
            return True, _last_line(self.job.result())
        # a failed command's error is its stderr, quoted between dashed lines of the trace
        text = str(error)
        quoted = text.split("-" * 22)[1] if text.count("-" * 22) >= 2 else text
        return False, _last_line(quoted).removeprefix("submitit.core.utils.FailedJobError: ")

    def stop(self) -> None:
        if self.cancel:  # SLURM signals the job's processes (SIGTERM), which checkpoint
            self.job.cancel(check=False)


def _submitit():
    try:
        import submitit
    except ImportError:
        raise SystemExit("run_grid: --submitit needs submitit: pip install "
                         "'flrjax[cluster]' (or submitit)") from None
    return submitit


def executor(args: argparse.Namespace, folder: str, name: str, time_limit: float | None):
    """The submitit executor of ``args.submitit``, its jobs' files in ``folder``: SLURM
    through ``AutoExecutor`` (partition, GPUs per job, time, extra sbatch options), or the
    ``LocalExecutor`` (given a slot's GPUs per job by :func:`run`)."""
    submitit = _submitit()
    if args.submitit == "local":
        ex = submitit.LocalExecutor(folder)
        ex.update_parameters(stderr_to_stdout=True, timeout_min=LOCAL_TIMEOUT_MIN)
        return ex
    if time_limit is None:
        raise SystemExit("run_grid: --submitit slurm needs --time-limit SECONDS (each job's; "
                         f"its SLURM time adds {SLURM_MARGIN_S // 60} min)")
    extra = dict(kv.split("=", 1) for kv in args.slurm_param if "=" in kv)
    if len(extra) != len(args.slurm_param):
        raise SystemExit(f"run_grid: --slurm-param takes KEY=VALUE, not {args.slurm_param}")
    try:
        ex = submitit.AutoExecutor(folder, cluster="slurm")
    except RuntimeError as e:  # no srun here
        raise SystemExit(f"run_grid: --submitit slurm: {e}") from None
    ex.update_parameters(name=name, nodes=1, tasks_per_node=1, stderr_to_stdout=True,
                         gpus_per_node=args.gpus_per_program,
                         timeout_min=math.ceil((time_limit + SLURM_MARGIN_S) / 60),
                         slurm_partition=args.slurm_partition,
                         slurm_additional_parameters=extra)
    return ex


def run(names: list[str], command: Command, args: argparse.Namespace, root: str,
        deadline: float | None, time_limit: float | None) -> None:
    """Run the programs ``names`` (``command`` gives each one's command line) as ``args`` place
    them, their logs under ``root``: at most one per slot at a time on this host (none started
    after ``deadline``, a ``time.perf_counter()``), or all at once as SLURM jobs of
    ``time_limit`` each. Raises :class:`Failed` if some failed, SystemExit on a signal."""
    if args.gpus_per_program < 1:
        raise SystemExit(f"run_grid: --gpus-per-program {args.gpus_per_program}")
    grid = os.path.basename(os.path.normpath(root))
    if args.submitit == "slurm":
        where: list[str | None] = [None] * len(names)
        deadline = None  # each job has its own clock
        ex = executor(args, os.path.join(root, "submitit", "%j"), grid, time_limit)
    else:
        where = slots(args) or [None]
        ex = args.submitit and executor(args, os.path.join(root, "submitit", "%j"), "", None)
        if args.submitit and not all(s is None or s.replace(",", "").isdigit() for s in where):
            raise SystemExit(f"run_grid: submitit's local executor takes GPU indices, not "
                             f"{','.join(map(str, where))}")

    def start(name: str, slot: str | None) -> _Process | _Job:
        left = None if deadline is None else deadline - time.perf_counter()
        argv = command(name, time_limit if args.submitit == "slurm" else left)
        if not ex:
            return _Process(argv, slot, os.path.join(root, "logs", f"{name}.log"))
        from submitit.helpers import CommandFunction

        if args.submitit == "local":
            gpus = [int(g) for g in slot.split(",")] if slot else []
            ex.update_parameters(visible_gpus=gpus, gpus_per_node=len(gpus))
        else:
            ex.update_parameters(name=f"{grid}.{name}")
        return _Job(ex.submit(CommandFunction(argv, cwd=os.getcwd())),
                    cancel=args.submitit == "slurm")

    _schedule(names, start, where, deadline, SLURM_POLL_S if args.submitit == "slurm" else POLL_S)


def _schedule(names: list[str], start: Callable[[str, str | None], _Process | _Job],
              where: list[str | None], deadline: float | None, poll: float) -> None:
    """Start each program when a slot is free, report each as it ends; see :func:`run`."""
    pending, free, running, failed = list(names), list(where), {}, []
    stopped: list[int] = []

    def on_signal(signum, frame):
        if stopped:  # a second signal: leave now
            raise SystemExit(128 + signum)
        stopped.append(signum)
        print(f"{signal.Signals(signum).name}: no more programs started; waiting for "
              f"{', '.join(running) or 'none'} to stop", file=sys.stderr, flush=True)
        for handle, _ in running.values():
            handle.stop()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        while running or (pending and not stopped):
            while pending and free and not stopped:
                if deadline is not None and time.perf_counter() >= deadline:
                    print(f"time limit: {', '.join(pending)} not started; run the same "
                          "command again", flush=True)
                    pending = []
                    break
                name, slot = pending.pop(0), free.pop(0)
                running[name] = (start(name, slot), slot)
                print(f"{name}: started on {running[name][0].where}, log "
                      f"{running[name][0].log}", flush=True)
            for name, (handle, slot) in list(running.items()):
                if handle.ended():
                    ok, line = handle.outcome()
                    print(f"{name} ({handle.where}): {line}" if ok else
                          f"{name} ({handle.where}) failed, {line}; log {handle.log}",
                          file=sys.stdout if ok else sys.stderr, flush=True)
                    failed += [] if ok else [name]
                    free.append(slot)
                    del running[name]
            if running:
                time.sleep(poll)
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    if stopped:
        print(f"stopped on {signal.Signals(stopped[0]).name}; run the same command again to "
              "continue", file=sys.stderr)
        raise SystemExit(128 + stopped[0])
    if failed:
        raise Failed(f"run_grid: {len(failed)} of {len(names)} programs failed: "
                     f"{', '.join(failed)} (their logs above)")
