"""The command line of ``python -m flrjax.train``: flags (grouped in ``--help``) to a
validated :class:`~flrjax.config.TrainConfig`, ``--resume``, the start line, the run and its
summary."""

from __future__ import annotations

import argparse
import decimal
import math
import os
import sys
import time
import warnings
from collections.abc import Callable
from typing import NamedTuple

import jax

from flrjax import algos, analysis, envs, metrics_io
from flrjax.config import (
    ALGOS,
    PRESETS,
    SWEEP_FIELDS,
    ConfigError,
    TrainConfig,
    default_preset,
    sweep_points,
    validate,
)
from flrjax.runner import (
    Stopped,
    TrainingFault,
    default_compile_cache,
    enable_compile_cache,
    train,
)


def int_value(text: str) -> int:
    """An integer flag's value in any notation that names an integer exactly (``1920000``,
    ``1.92e6``, ``1e9``); anything else (``1.5e0``, ``two``) is refused in one line."""
    try:
        value = decimal.Decimal(text.strip())
    except decimal.InvalidOperation:
        value = None
    if value is None or not value.is_finite() or value != value.to_integral_value():
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer")
    return int(value)


def _floats(text: str) -> float | tuple[float, ...]:
    """A flag's number, or a tuple of them from a comma-separated list (a sweep)."""
    values = tuple(float(x) for x in text.split(","))
    return values if "," in text else values[0]


def _strs(text: str) -> str | tuple[str, ...]:
    """A flag's word, or a tuple of them from a comma-separated list (a sweep)."""
    values = tuple(x.strip() for x in text.split(","))
    return values if "," in text else values[0]


def _sweep(text: str) -> tuple[tuple[tuple[str, float | int | str], ...], ...]:
    """``--sweep "flr-alpha=0; flr-eps=0.5, flr-alpha=0.001"``: points split by ``;``, each
    a comma-separated list of FIELD=VALUE (flags' names, with - or _)."""
    points = []
    for part in text.split(";"):
        point = []
        for item in filter(None, (x.strip() for x in part.split(","))):
            name, eq, value = item.partition("=")
            field = name.strip().removeprefix("--").replace("-", "_")
            if not eq or field not in SWEEP_FIELDS:
                raise argparse.ArgumentTypeError(
                    f"{item!r}: each point is FIELD=VALUE[, ...] with FIELD one of "
                    f"{', '.join(f.replace('_', '-') for f in SWEEP_FIELDS)}")
            parse = {int: int_value}.get(SWEEP_FIELDS[field].type, SWEEP_FIELDS[field].type)
            try:
                point.append((field, parse(value.strip())))
            except (ValueError, argparse.ArgumentTypeError):
                kind = "an integer" if parse is int_value else "a number"
                raise argparse.ArgumentTypeError(f"{item!r}: not {kind}") from None
        if point:
            points.append(tuple(point))
    return tuple(points)


def _ints(text: str) -> int | tuple[int, ...]:
    """A flag's integer, or a tuple of them from a comma-separated list (a sweep)."""
    values = tuple(int_value(x) for x in text.split(","))
    return values if "," in text else values[0]


#: The sized and tuned flags: type and help. Each is checked by :func:`validate`.
FLAG_HELP: dict[str, tuple[Callable[[str], object], str]] = {
    "steps": (int_value, "env steps per seed (all its envs); a multiple of envs x episode "
                         "length x episodes per chunk; 1.92e6 and the like are accepted"),
    "num_envs": (int_value, "lockstep envs per seed; shapes the program: one value"),
    "updates_per_step": (float, "gradient updates per env step (paper protocol: 1 with 1 env)"),
    "episodes_per_chunk": (int_value, "episode rounds per jitted chunk (one evaluation each)"),
    "eval_episodes": (int_value, "deterministic test episodes per evaluation (paper: 10)"),
    "batch_size": (int_value, "TD3 batch (reference: 1024); shapes the program: one value"),
    "hidden": (int_value, "width of the 3 hidden layers (reference: 256); shapes the "
                          "program: one value"),
    "buffer_episodes": (int_value, "replay capacity in episodes, per seed; shapes the "
                                   "program: one value"),
    "initial_episodes": (_ints, "random-action episodes before learning (DHRL: 200); "
                                "comma-separated values sweep it in one vmapped run"),
    "lr_actor": (_floats, "Adam learning rate of the low level's actor (flat's, PIG's; "
                          "reference 1e-4); comma-separated values sweep it"),
    "lr_critic": (_floats, "Adam learning rate of the low level's critics (reference 1e-3); "
                           "comma-separated values sweep it"),
    "high_lr_actor": (_floats, "dhrl, flr_dhrl, higl: the high level's actor learning rate "
                               "(reference 1e-4); comma-separated values sweep it"),
    "high_lr_critic": (_floats, "dhrl, flr_dhrl, higl: the high level's critic learning rate "
                                "(reference 1e-3); comma-separated values sweep it"),
    "polyak": (_floats, "target networks of every level: t <- polyak t + (1 - polyak) online; "
                        "comma-separated values sweep it"),
    "target_update_freq": (int_value, "updates between target-network steps (reference: 10)"),
    "gamma": (_floats, "discount of every level (default: the reference's 0.99, HIGL's "
                       "controller 0.95); comma-separated values sweep it"),
    "noise_eps": (_floats, "the low level's Gaussian exploration std, times the action bound "
                           "(reference 0.1); comma-separated values sweep it"),
    "target_noise": (_floats, "the low level's target-policy smoothing std (default 0.05/30, "
                              "the reference's 0.05 on torques of +-30); comma-separated "
                              "values sweep it"),
    "future_p": (_floats, "flat, dhrl, flr_*, pig: chance that the low level's HER relabels a "
                          "batch's goal (default: the reference's 0.8); comma-separated "
                          "values sweep it"),
    "train_precision": (str, "matrix operands of both levels' updates (forward and "
                             "gradients), float32 or bfloat16 (float32 accumulation, "
                             "parameters and Adam; default: bfloat16 for dhrl and flr_dhrl "
                             "on a GPU, float32 otherwise)"),
    "episode_length": (int_value, "override the env's episode length"),
    "goal_radius": (float, "ant only: training goals within this of the start"),
    "subgoal_freq": (int_value, "dhrl: env steps per subgoal (ant: 40)"),
    "graph_start_steps": (int_value, "graph algos: env steps per seed before the first graph"),
    "graph_every_steps": (int_value, "graph algos: env steps per seed between rebuilds "
                                     "(ant: 9000)"),
    "cutoff": (float, "graph algos: longest graph edge, in estimated steps (ant: 30)"),
    "landmark_eps": (float, "graph algos: FPS stops once every state is this close (ant: 10)"),
    "max_landmarks": (int_value, "graph algos: most graph nodes (ant: 300)"),
    "landmark_sample": (int_value, "graph algos: replay states FPS picks from (ant: 6000)"),
    "checkpoint_every": (int_value, "chunks between checkpoints; 0 keeps none (default 1)"),
    "flr_alpha": (_floats, "flr_*: alpha of eq. 5 (paper 0.01; > 1 - gamma warns); "
                           "comma-separated values sweep it in one vmapped run"),
    "flr_eps": (_floats, "flr_*: next subgoals at distance >= eps (paper 2; <= 2 delta "
                         "warns); comma-separated values sweep it"),
    "flr_next": (_strs, "flr_*: 'sample' next subgoals on the eps ring, or the final 'goal'; "
                        "'sample,goal' sweeps it"),
    "flr_candidates": (int_value, "flr_*: next subgoals sampled per transition (default 16)"),
    "flr_value_chunk": (int_value, "flr_*: reaching transitions per V evaluation chunk "
                                   "(default: the whole batch on a GPU, 128 on a CPU; 0: the "
                                   "whole batch)"),
    "flr_precision": (str, "flr_*: matrix operands of eq. 5's candidate values, float32 or "
                           "bfloat16 (float32 accumulation; default: bfloat16 on a GPU, "
                           "float32 on a CPU)"),
    "value_kernel": (str, "dhrl, flr_*: eq. 5's candidate values and subgoal testing's "
                          "distances (an actor and twin critics on many rows) as one XLA "
                          "kernel per layer ('xla') or one fused kernel ('fused', bfloat16 "
                          "operands only; default: fused on one GPU, xla on a CPU "
                          "or several GPUs)"),
    "subgoal_test_precision": (str, "dhrl, flr_dhrl: matrix operands of subgoal testing's "
                                    "landmark distances, float32 or bfloat16 (float32 "
                                    "accumulation; default: bfloat16 on a GPU, float32 on a "
                                    "CPU)"),
    "pig_jump_temp": (_floats, "pig, flr_pig: subgoal skipping, each hop with probability "
                               "jump_temp / imitation loss (default 10/30**2, the reference's "
                               "10 on torques of +-30; 0: off); comma-separated values sweep it"),
    "low_value": (str, "dhrl, flr_*, pig: the low level's value; 'infinite' bootstraps "
                       "through every transition (DHRL's code, the default), 'reach_ends' "
                       "ends a subgoal's episode where the transition reaches it, 'k_step' "
                       "(dhrl, flr_dhrl) sums the subgoal period's k steps (the paper's "
                       "V^l: the policy sees the steps left)"),
    "sweep": (_sweep, "sweep points, each FIELD=VALUE[, ...], split by ';' (e.g. 'flr-alpha=0; "
                      "lr-critic=3e-4'); a field a point omits keeps its flag's value; "
                      f"sweepable: {', '.join(f.replace('_', '-') for f in SWEEP_FIELDS)}"),
    "devices": (int_value, "devices the seeds are sharded over (default: all that divide --seeds)"),
}


#: ``--help``'s groups of :data:`FLAG_HELP`'s flags (run flags and checkpoints add their own).
FLAG_GROUPS: dict[str, tuple[str, ...]] = {
    "run": ("steps", "devices"),
    "learner (sizes: the preset's unless given)": (
        "num_envs", "updates_per_step", "episodes_per_chunk", "eval_episodes", "batch_size",
        "hidden", "buffer_episodes", "initial_episodes", "target_update_freq",
        "train_precision", "value_kernel", "episode_length", "goal_radius", "low_value"),
    "learner numbers (each run's own: a comma list trains them as sweep points in one "
    "program)": (
        "lr_actor", "lr_critic", "high_lr_actor", "high_lr_critic", "polyak", "gamma",
        "noise_eps", "target_noise", "future_p"),
    "graph and DHRL (dhrl, flr_dhrl, pig, flr_pig, higl; default: the env's)": (
        "subgoal_freq", "graph_start_steps", "graph_every_steps", "cutoff", "landmark_eps",
        "max_landmarks", "landmark_sample", "subgoal_test_precision"),
    "FLR (flr_dhrl, flr_pig)": ("flr_alpha", "flr_eps", "flr_next", "flr_candidates",
                                "flr_value_chunk", "flr_precision"),
    "PIG (pig, flr_pig)": ("pig_jump_temp",),
    "sweeps": ("sweep",),
    "checkpoints": ("checkpoint_every",),
}


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
    """argparse with one-line errors: the usage block would bury the message."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _preset_values(name: str) -> str:
    """``[quick 24000, paper 1200000, fast 1920000]`` for a flag the presets set, else its
    default where the help does not say it."""
    vals = [f"{p} {v[name]}" for p, v in PRESETS.items() if name in v]
    if vals:
        return f" [{', '.join(vals)}]"
    default = TrainConfig.__dataclass_fields__[name].default
    return "" if default is None or "default" in FLAG_HELP[name][1] else f" (default {default})"


def _parser() -> _Parser:
    p = _Parser(prog=PROG,
                description="Train a method of the paper on a maze: seeds and sweep points "
                            "vmapped in one jitted program.")
    run = p.add_argument_group("run")
    run.add_argument("--env", default=None,
                     help=f"one of {', '.join(envs.names())} (default {TrainConfig.env})")
    run.add_argument("--algo", default=None,
                     help=f"one of {', '.join(ALGOS)} (default {TrainConfig.algo})")
    run.add_argument("--preset", choices=["auto", *PRESETS], default="auto",
                     help="the sizes below: auto (default) is fast on a GPU, quick on a CPU")
    run.add_argument("--seeds", type=int_value, default=None,
                     help="seeds trained at once, vmapped (default 1)")
    run.add_argument("--seed", type=int_value, default=None, help="base random seed (default 0)")
    run.add_argument("--out", default=None,
                     help="run directory (default runs/<env>-<algo>-<date>-<time>)")
    run.add_argument("--tensorboard", action="store_true",
                     help="also write TensorBoard event files into the run directory")
    run.add_argument("--deterministic", action="store_true", default=None,
                     help="on a GPU, the same numbers for the same seed every time (XLA's "
                          "scatters without atomics, which make each step slower); a CPU "
                          "always repeats")
    groups = {name: (run if name == "run" else p.add_argument_group(name))
              for name in FLAG_GROUPS}
    for name, fields in FLAG_GROUPS.items():
        for field in fields:
            typ, text = FLAG_HELP[field]
            groups[name].add_argument("--" + field.replace("_", "-"), type=typ, default=None,
                                      help=text + _preset_values(field))
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
    cache = None if args.no_compile_cache else default_compile_cache()
    tensorboard = args.tensorboard
    del args.time_limit, args.no_compile_cache, args.tensorboard
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
    cfg = TrainConfig(**kw)
    try:
        validate(cfg)
        metrics_io.check_out(cfg, new_run=False)
    except ConfigError as e:
        p.error(str(e))
    return CLI(cfg, False, time_limit, cache, preset, tensorboard)


def _resume_config(p: argparse.ArgumentParser, args: argparse.Namespace) -> TrainConfig:
    """The config saved in ``--resume DIR``; flags given with it must agree with it."""
    try:
        saved, saved_json = metrics_io.read_run_config(args.resume)
    except ConfigError as e:
        p.error(f"--resume: {e}")
    if "resolved" in saved_json:  # a run saved before config.json had it has nothing to compare
        _warn_resolved_changes(saved_json["resolved"], saved)
    given = {k: v for k, v in vars(args).items()
             if k not in ("resume", "preset", "out") and v is not None}
    differ = sorted(k for k, v in given.items() if v != getattr(saved, k))
    if differ:
        p.error(f"--resume: the run in {args.resume} was started with different "
                f"{', '.join(differ)}; drop those flags")
    return saved


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
    return (f"{analysis.METHOD_NAMES[cfg.algo]} ({cfg.algo}) on "
            f"{analysis.env_name(cfg.env)} ({cfg.env}), {runs}, {what}: "
            f"{cfg.steps:,} env steps per seed in {plural(chunks, 'chunk')} of "
            f"{cfg.steps_per_chunk:,}, {plural(cfg.num_envs, 'env')} per seed, "
            f"{plural(cfg.updates_per_step, 'update')} per env step "
            f"({algos.train_precision(cfg)} matrix operands); "
            f"{jax.devices()[0].device_kind} ({jax.default_backend()}). The first chunk "
            "compiles; the progress bar's estimate of the time left follows it.")


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
    cli = parse_cli(argv)
    cfg = cli.cfg
    enable_compile_cache(cli.compile_cache)
    print(start_line(cli), flush=True)
    board = (metrics_io.TensorBoard(cfg.out, cfg.algo, sweep_points(cfg), cfg.seeds)
             if cli.tensorboard else None)
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
    if not rows:
        print(f"nothing to do: the run in {cfg.out} has all its {cfg.steps:,} steps")
        return
    head = ("done" if rows[-1]["step"] == cfg.steps else
            f"time limit: stopped with a checkpoint (continue: {PROG} --resume {cfg.out})")
    print(f"{head}: {metrics_io.format_summary(finish(cfg, rows))}")
