"""The command line of ``python -m flrjax.train``: flags (grouped in ``--help``) to a
validated :class:`~flrjax.config.TrainConfig`, ``--resume``, the start line, the run and its
summary."""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
import warnings
from typing import NamedTuple

import jax

from flrjax import algos, analysis, checkpoint, distributed, envs, metrics_io
from flrjax.algos.common import num_devices, padded_runs, train_precision
from flrjax.config import (
    ConfigError,
    TrainConfig,
    all_flags,
    flag_defaults,
    make,
    sweep_fields,
    sweep_points,
    takers,
)
from flrjax.launch_cache import default_compile_cache, enable_compile_cache
from flrjax.options import Flag, dashed, parser
from flrjax.presets import PRESETS, default_preset
from flrjax.runner import TrainingFault, train
from flrjax.stops import Stopped
from flrjax.validation import validate


def parse_args(argv: list[str] | None = None) -> TrainConfig:
    """CLI flags -> a validated :class:`TrainConfig` (exits with a one-line error if bad)."""
    return parse_cli(argv).cfg


class CLI(NamedTuple):
    """What the command line asks for: the run and how to drive it."""

    cfg: TrainConfig  # validated
    resume: bool
    time_limit: float | None  # seconds
    compile_cache: str | None  # None: compiled programs are not kept between runs
    preset: str | None = None  # the preset the sizes came from (None when resuming)
    tensorboard: bool = False


#: The command, as its messages name it.
PROG = "python -m flrjax.train"


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (the usage block would bury the message), and values
    that start with a minus in any number notation read as values: before Python 3.13
    argparse takes ``--lr-critic -1e-3`` (or ``-1,2``) for a flag missing its value."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d[\d.eE+\-,]*$")

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _preset_values(name: str, f: Flag, default) -> str:
    """``[quick 24000, paper 1200000, fast 1920000]`` for a flag the presets set, else its
    default where the help does not say it."""
    vals = [f"{p} {v[name]}" for p, v in PRESETS.items() if name in v]
    if vals:
        return f" [{', '.join(vals)}]"
    if default is None or f.type is bool or "default" in f.help:
        return ""
    return f" (default {default})"


def _applies_to(names: list[str]) -> str:
    """``dhrl, flr_dhrl`` for flags some methods take, ``""`` for flags of every method."""
    who = dict.fromkeys(m for n in names for m in takers(n))
    return "" if set(who) == set(algos.names()) else ", ".join(who)


def _help(name: str, f: Flag, default, section_takers: str) -> str:
    """A flag's --help line: the methods it applies to (where not all, nor its section's
    title says), its text, its presets' values or default."""
    who = _applies_to([name])
    where = f"{who}: " if who and who != section_takers else ""
    text = {"env": f"one of {', '.join(envs.names())}",
            "algo": f"one of {', '.join(algos.names())}",
            "sweep": f"{f.help}; sweepable: "
                     f"{', '.join(k.replace('_', '-') for k in sweep_fields())}",
            "train_precision": f"{f.help} ("
                               f"{', '.join(m.name for m in algos.methods() if m.train_bf16_gpu)})",
            }.get(name, f.help)
    return where + text + _preset_values(name, f, default)


#: --help's sections in order (a flag's own names its section; new ones follow these).
GROUPS = ("run", "learner (sizes: the preset's unless given)",
          "learner numbers (each run's own: a comma list trains them as sweep points in one "
          "program)")


def _parser() -> _Parser:
    """The command line, generated from the flags of :class:`TrainConfig` and of every
    registered method's options (:func:`flrjax.config.all_flags`), grouped by their
    sections; a method's flags name the methods that take them."""
    p = _Parser(prog=PROG,
                description="Train a method of the paper on a maze: seeds and sweep points "
                            "vmapped in one jitted program.")
    flags, defaults = all_flags(), flag_defaults()
    sections = list(dict.fromkeys([*GROUPS, *(f.group for f in flags.values())]))
    sections = [s for s in sections if s not in ("sweeps", "checkpoints")]
    members = {s: [k for k, f in flags.items() if f.group == s]
               for s in [*sections, "sweeps", "checkpoints"]}
    who = {s: _applies_to(names) for s, names in members.items()}
    groups = {s: p.add_argument_group(f"{s} ({who[s]})" if who[s] else s) for s in members}
    groups["run"].add_argument(
        "--preset", choices=["auto", *PRESETS], default="auto",
        help="the sizes below: auto (default) is tuned on a GPU, quick on a CPU")
    groups["run"].add_argument("--tensorboard", action="store_true",
                               help="also write TensorBoard event files into the run directory")
    for name, f in flags.items():
        kw = (dict(action=argparse.BooleanOptionalAction) if f.type is bool else
              dict(type=parser(f)))
        groups[f.group].add_argument(dashed(name), default=None,
                                     help=_help(name, f, defaults[name], who[f.group]), **kw)
    ck = groups["checkpoints"]
    ck.add_argument("--resume", metavar="DIR", default=None,
                    help="continue the run in DIR from its newest checkpoint (its own config)")
    ck.add_argument("--time-limit", metavar="SECONDS", type=float, default=None,
                    help="stop cleanly, with a checkpoint, before a chunk that would end past "
                         "SECONDS; continue later with --resume")
    ck.add_argument("--no-compile-cache", action="store_true",
                    help="do not keep compiled and traced programs between runs (default: "
                         f"kept in {default_compile_cache()} and beside it in ...-programs, so "
                         "a second launch skips tracing and compiling)")
    hosts = p.add_argument_group(
        "several hosts (jax.distributed; --out on a file system every process sees)")
    hosts.add_argument(
        "--distributed", action="store_true",
        help="one run over several processes, one per host (or per GPU), each started with the "
             "same flags: the runs are split over every process's devices, process 0 writes "
             "the run's files. Found by itself under SLURM's srun and Open MPI's mpirun (and "
             "then on by default when they start several processes); elsewhere give the three "
             "flags below")
    hosts.add_argument("--coordinator", metavar="HOST:PORT", default=None,
                       help="process 0's address, the same for every process (implies "
                            "--distributed)")
    hosts.add_argument("--num-processes", metavar="N", type=int, default=None,
                       help="how many processes take part (implies --distributed)")
    hosts.add_argument("--process-id", metavar="I", type=int, default=None,
                       help="this process's number, 0..N-1 (implies --distributed)")
    return p


def _format_warning(message: Warning | str, category: type[Warning], filename: str,
                    lineno: int, line: str | None = None) -> str:
    """A warning as one line, ``python -m flrjax.train: warning: MESSAGE`` (its category
    named unless a :class:`UserWarning`), in place of Python's file, line and source line."""
    kind = "warning" if issubclass(category, UserWarning) else category.__name__
    return f"{PROG}: {kind}: {' '.join(str(message).split())}\n"


def one_line_warnings() -> None:
    """Show every warning of this process as one line (:func:`_format_warning`)."""
    warnings.formatwarning = _format_warning


def parse_cli(argv: list[str] | None = None) -> CLI:
    """CLI flags -> :class:`CLI`; one-line errors on bad input, before anything is written,
    and one-line warnings from here on (:func:`one_line_warnings`)."""
    one_line_warnings()
    p = _parser()
    try:
        args = p.parse_args(argv)
    except SystemExit as e:  # argparse already printed its one-line usage error
        raise SystemExit(e.code) from None
    time_limit = args.time_limit
    if time_limit is not None and not (math.isfinite(time_limit) and time_limit > 0):
        p.error("--time-limit must be a positive number of seconds")
    try:  # before anything touches JAX's backend (the preset, the checks)
        distributed.initialize(args.distributed, args.coordinator, args.num_processes,
                               args.process_id)
    except ConfigError as e:
        p.error(str(e))
    cache = None if args.no_compile_cache else default_compile_cache()
    tensorboard = args.tensorboard
    del (args.time_limit, args.no_compile_cache, args.tensorboard, args.distributed,
         args.coordinator, args.num_processes, args.process_id)
    if args.resume is not None:
        return CLI(_resume_config(p, args), True, time_limit, cache, None, tensorboard)
    preset = default_preset() if args.preset == "auto" else args.preset
    kw = dict(PRESETS[preset])
    for k, v in vars(args).items():
        if k != "preset" and v is not None:
            kw[k] = v
    if kw.get("out") is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        kw["out"] = os.path.join("runs", f"{kw.get('env', TrainConfig.env)}-"
                                         f"{kw.get('algo', TrainConfig.algo)}-{stamp}")
    try:
        cfg = make(kw)
        validate(cfg)
        metrics_io.check_out(cfg, new_run=False)
    except ConfigError as e:
        p.error(str(e))
    return CLI(cfg, False, time_limit, cache, preset, tensorboard)


def _resume_config(p: argparse.ArgumentParser, args: argparse.Namespace) -> TrainConfig:
    """The config saved in ``--resume DIR``; flags given with it must agree with it, but
    ``--devices``, which places the runs and leaves what they compute as it was (a run may
    continue on another machine)."""
    try:
        saved, saved_json = metrics_io.read_run_config(args.resume)
    except ConfigError as e:
        p.error(f"--resume: {e}")
    if args.out is not None and os.path.realpath(args.out) != os.path.realpath(args.resume):
        p.error(f"--resume continues the run in {args.resume} there; drop --out {args.out}")
    given = {k: v for k, v in vars(args).items()
             if k not in ("resume", "preset", "out", "devices") and v is not None}
    differ = sorted(k for k, v in given.items() if v != getattr(saved, k, None))
    if differ:
        p.error(f"--resume: the run in {args.resume} was started with different "
                f"{', '.join(differ)}; drop those flags")
    checkpoint.read_ahead(args.resume)  # while the env and the programs are built
    if "resolved" in saved_json:  # a run saved before config.json had it has nothing to compare
        _warn_resolved_changes(saved_json["resolved"], saved)
    cfg = saved if args.devices is None else saved.replace(devices=args.devices)
    try:
        validate(cfg)
    except ConfigError as e:
        p.error(f"--resume: {e}")
    return cfg


def _warn_resolved_changes(before: dict, cfg: TrainConfig) -> None:
    """Warn when a resumed run's device-dependent defaults resolve otherwise than when it
    started (config.json's ``resolved``; e.g. a GPU run resumed on a CPU): it continues,
    computing with the new ones."""
    now = metrics_io.resolved_settings(cfg)
    changed = [f"{k} {before[k]} -> {now[k]}" for k in sorted(before)
               if k in now and before[k] != now[k]]
    if changed:
        warnings.warn(f"--resume: this run continues with other defaults than it started "
                      f"with: {'; '.join(changed)}", stacklevel=2)


def start_line(cli: CLI) -> str:
    """What a run is about to do, printed before it compiles."""
    cfg = cli.cfg
    chunks = cfg.steps // cfg.steps_per_chunk
    what = "resuming" if cli.resume else f"preset {cli.preset}"
    plural = analysis.plural
    runs = plural(cfg.seeds, "seed") + (f" x {cfg.runs // cfg.seeds} sweep points"
                                        if cfg.runs > cfg.seeds else "")
    return (f"{analysis.method_name(cfg.algo)} ({cfg.algo}) on "
            f"{analysis.env_name(cfg.env)} ({cfg.env}), {runs}, {what}: "
            f"{cfg.steps:,} env steps per seed in {plural(chunks, 'chunk')} of "
            f"{cfg.steps_per_chunk:,}, {plural(cfg.num_envs, 'env')} per seed, "
            f"{plural(cfg.updates_per_step, 'update')} per env step "
            f"({train_precision(cfg)} matrix operands){_initial_rounds(cfg)}; "
            f"{_devices(cfg)}. The first chunk "
            "compiles; the progress bar's estimate of the time left follows it.")


def _initial_rounds(cfg: TrainConfig) -> str:
    """``, 192 initial random episodes run as 256 (whole rounds of 128 envs)`` where
    ``--initial-episodes`` is not a multiple of ``--num-envs``."""
    given = dict.fromkeys(p.get("initial_episodes", cfg.initial_episodes)
                          for p in sweep_points(cfg))  # a sweep's values, in its order
    odd = [f"{v} as {-(-v // cfg.num_envs) * cfg.num_envs}" for v in given
           if v % cfg.num_envs]
    return (f", initial random episodes run {', '.join(odd)} (whole rounds of "
            f"{analysis.plural(cfg.num_envs, 'env')})") if odd else ""


def _devices(cfg: TrainConfig) -> str:
    """``NVIDIA H100 (gpu)``, or over several: ``4 x NVIDIA H100 (gpu) in 2 processes, the
    runs padded with 2 spare ones``."""
    n, pad = num_devices(cfg), padded_runs(cfg) - cfg.runs
    kind = f"{jax.devices()[0].device_kind} ({jax.default_backend()})"
    procs = f" in {jax.process_count()} processes" if jax.process_count() > 1 else ""
    spare = (f", the runs padded with {analysis.plural(pad, 'spare one')} (dropped from every "
             "output)") if pad else ""
    return (f"{n} x {kind}" if n > 1 else kind) + procs + spare


def finish(cfg: TrainConfig, rows: list[dict]) -> dict:
    """Write ``curves.png`` and ``summary.json`` into the run directory; the summary."""
    points = sweep_points(cfg)
    metrics_io.plot_curves(cfg.algo, points, cfg.seeds, rows,
                           os.path.join(cfg.out, "curves.png"), cfg.env, cfg.steps)
    path = os.path.join(cfg.out, "summary.json")
    summary = metrics_io.summarize(cfg.algo, points, cfg.seeds, cfg.steps, rows, cfg.out)
    summary["files"] = dict(sorted({**summary["files"], "summary.json": path}.items()))
    metrics_io.write_json(path, summary)
    return summary


def main(argv: list[str] | None = None) -> None:
    """The command line's run. Under ``jax.distributed`` every process runs it; process 0
    alone prints the start line and summary and writes the run's files."""
    cli = parse_cli(argv)
    cfg = cli.cfg
    main_process = distributed.is_main()
    enable_compile_cache(cli.compile_cache)
    if main_process:
        print(start_line(cli), flush=True)
    board = (metrics_io.TensorBoard(cfg.out, cfg.algo, sweep_points(cfg), cfg.seeds)
             if cli.tensorboard and main_process else None)
    try:
        rows = train(cfg, resume=cli.resume, time_limit=cli.time_limit,
                     progress_fn=board and (lambda step, rows: board.write(step, rows)))
    except ConfigError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except TrainingFault as e:
        print(f"{PROG}: stopped: {e}", file=sys.stderr)
        raise SystemExit(3) from None
    except Stopped as e:  # SIGINT or SIGTERM: exit 128 + its number, as the shell has it
        resume = f" (continue: {PROG} --resume {e.out})" if e.out else ""
        print(f"{PROG}: {e}{resume}", file=sys.stderr)
        raise SystemExit(128 + e.signum) from None
    finally:
        if board is not None:
            board.close()
    if not main_process:
        return
    if not rows:
        print(f"nothing to do: the run in {cfg.out} has all its {cfg.steps:,} steps")
        return
    head = ("done" if rows[-1]["step"] == cfg.steps else
            f"time limit: stopped with a checkpoint (continue: {PROG} --resume {cfg.out})")
    print(f"{head}: {metrics_io.format_summary(finish(cfg, rows))}")
