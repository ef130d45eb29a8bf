"""The host loop over jitted chunks (between them: evaluation, the check for non-finite values,
metrics.csv, progress, checkpoints), the jitted programs, their sharding over devices and the
memory check."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import algos, checkpoint, distributed, launch_cache, metrics_io, stops
from flrjax.algos.common import num_devices, padded_runs
from flrjax.config import (
    ConfigError,
    TrainConfig,
    make_env,
    point_name,
    program_config,
    run_flags,
    sweep_points,
)
from flrjax.metric_names import TIMES, columns, is_learner
from flrjax.run_axis import pad_runs, real_runs, run_keys, shard_seeds, vmap_runs
from flrjax.sweep import run_hparams, run_values
from flrjax.validation import validate

#: XLA options of the trainer's programs. A CUDA graph's kernels are ordered by their buffers'
#: dependencies only (XLA's default keeps the schedule's order), so that independent small
#: kernels, e.g. the main and distance critics' steps and eq. 5's values, run side by side;
#: with deterministic scatters the results are bit for bit the serial order's, so only the
#: speed changes (docs/benchmarks.md). Other backends ignore it.
COMPILER_OPTIONS = {"xla_gpu_command_buffer_scheduling_mode": "CONCURRENT"}
#: Added for ``--deterministic``: scatters without atomics, so that a GPU run repeats.
DETERMINISTIC_OPTIONS = {"xla_gpu_deterministic_ops": True}


def compiler_options(cfg: TrainConfig) -> dict:
    """XLA's options for ``cfg``'s programs."""
    return {**COMPILER_OPTIONS, **(DETERMINISTIC_OPTIONS if cfg.deterministic else {})}


def build(cfg: TrainConfig) -> tuple[Callable, Callable, Callable]:
    """(init(keys[S]), chunk(carry[S], first_episode), evaluate(carry[S], keys[S])), jitted.

    Cached on the fields that shape the computation (:func:`_shape_key`), so runs that differ
    only in seed, length, output directory, checkpoints or the learners' numbers the states
    carry reuse the compiled programs; ``init`` puts ``cfg``'s numbers into the states.
    """
    init, chunk, evaluate = _build(_shape_key(cfg))
    return init.bind(_hparams(cfg)), chunk, evaluate


@functools.cache
def _hparams(cfg: TrainConfig):
    """Each run's learner numbers, the padding runs' too (host arrays)."""
    return pad_runs(cfg, run_hparams(cfg, make_env(cfg)))


def in_state_fields(cfg: TrainConfig) -> tuple[str, ...]:
    """The sweepable fields of ``cfg``'s method that the agents' states carry
    (:attr:`flrjax.options.Sweepable.in_state`): ``init`` takes them as an argument, so the
    programs do not depend on their values."""
    return tuple(k for k, f in run_flags(cfg).items() if f.sweep is not None and f.sweep.in_state)


def _shape_key(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` without what does not shape the programs: seed, length, output, checkpoints,
    and the values of the learners' numbers the states carry (:func:`in_state_fields`), each
    set to its default (a swept one to as many defaults: the runs and points stay)."""
    keep = in_state_fields(cfg)
    default = {f.name: f.default for f in (*dataclasses.fields(cfg.options or TrainConfig),
                                          *dataclasses.fields(TrainConfig)) if f.name in keep}
    values = {k: (default[k],) * len(v) if isinstance(v := getattr(cfg, k), tuple)
              else default[k] for k in keep}
    sweep = cfg.sweep and tuple(tuple((k, default[k] if k in keep else v) for k, v in p)
                                for p in cfg.sweep)
    return cfg.replace(out=None, seed=0, steps=cfg.steps_per_chunk,
                       checkpoint_every=TrainConfig.checkpoint_every, sweep=sweep, **values)


class WithHparams:
    """A program of (keys, hparams) called, lowered and shaped as one of keys alone, with one
    config's learner numbers (:func:`flrjax.sweep.run_hparams`, ``[padded_runs]`` leaves,
    placed as the keys are: each process its own part, under ``jax.distributed``). Inside
    another trace (``jax.eval_shape`` of it) its function ``fn`` is traced in place: a
    program compiled with XLA options cannot be nested."""

    def __init__(self, program: Callable, fn: Callable, hparams=None, carry=None):
        self.program, self.fn, self.hparams, self._carry = program, fn, hparams, carry

    def bind(self, hparams) -> WithHparams:
        """This program with ``hparams``."""
        return WithHparams(self.program, self.fn, hparams, self._carry)

    def __call__(self, keys):
        if isinstance(keys, jax.core.Tracer):
            return self.fn(keys, self.hparams)
        where = getattr(keys, "sharding", None)
        return self.program(keys, self.hparams if where is None else jax.tree.map(
            lambda x: distributed.put(x, where), self.hparams))

    def lower(self, keys):
        """Lowered for ``keys`` (arrays or shapes), the hparams placed as a call places them,
        so that compiling it ahead compiles the program a call then runs."""
        return self.program.lower(keys, _specs(self.hparams, getattr(keys, "sharding", None)))

    def eval_shape(self, keys):
        return self.program.eval_shape(keys, _specs(self.hparams))

    def carry_shapes(self, keys):
        """A call's outputs as placed ``ShapeDtypeStruct``s, without running it: a stored
        program's as :func:`_stored` placed them for the chunk, a jitted one's by JAX."""
        return self.eval_shape(keys) if self._carry is None else self._carry


def _specs(tree, sharding=None):
    """``tree``'s leaves as ``ShapeDtypeStruct``s, placed by ``sharding`` if given."""
    return jax.tree.map(lambda x: jax.ShapeDtypeStruct(np.shape(x), x.dtype, sharding=sharding),
                        tree)


@functools.cache
def _build(cfg: TrainConfig) -> tuple[Callable, Callable, Callable]:
    env, algo = make_env(cfg), algos.get(cfg.algo)
    acfg = program_config(cfg, env=env)
    values = pad_runs(cfg, run_values(cfg))

    def with_values(v: dict):  # one run's algo config, with its traced swept values
        return program_config(cfg, v, env) if v else acfg

    def chunk(carry, first_episode):
        episodes = first_episode + jnp.arange(cfg.episodes_per_chunk)

        def one_run(c, v):
            run_cfg = with_values(v)
            return jax.lax.scan(lambda c, e: algo.train_episode(c, e, env, run_cfg), c,
                                episodes)

        return vmap_runs(cfg, one_run)(carry, values)

    # Every output split along the run axis over the devices, as the inputs are: left to
    # itself, XLA may lay out some leaves otherwise (replicated, or with another spec), and
    # the next chunk would recompile for the changed input layout.
    seeds = shard_seeds(cfg)

    def init(keys, hparams):  # each run with its point's learner numbers
        return vmap_runs(cfg, lambda k, hp: algo.init(k, env, acfg, hp))(keys, hparams)

    def evaluate(carry, keys):  # with each run's values too: some act at test time (PIG's)
        return vmap_runs(cfg, lambda c, k, v: algo.evaluate(c, k, env, with_values(v)))(
            carry, keys, values)

    hparams = _specs(pad_runs(cfg, run_hparams(cfg, env)))
    s_init, s_chunk, s_eval, carry = _stored(cfg, seeds, init, chunk, evaluate, hparams)
    return WithHparams(s_init, init, carry=carry), s_chunk, s_eval


def _stored(cfg: TrainConfig, seeds, init: Callable, chunk: Callable, evaluate: Callable,
            hparams) -> tuple[Callable, Callable, Callable, Any]:
    """The three functions (not jitted) as stored by an earlier launch of this config where
    :mod:`flrjax.launch_cache` has them (exported now where it does not), else jitted here,
    each output split over the devices by ``seeds``; and the carry's placed shapes (None when
    jitted). Under ``jax.distributed`` the programs are traced as before."""
    options = compiler_options(cfg)
    jit = functools.partial(jax.jit, compiler_options=options, out_shardings=seeds)
    jitted = (jit(init), jit(chunk, donate_argnums=0), jit(evaluate))
    split = num_devices(cfg) > 1

    def shaped(tree):  # as the programs take them: split over the devices where they are
        return jax.tree.map(lambda x: jax.ShapeDtypeStruct(
            x.shape, x.dtype, sharding=seeds if split else None), tree)

    keys, hparams = shaped(jax.ShapeDtypeStruct((padded_runs(cfg), 2), jnp.uint32)), \
        shaped(hparams)
    store = functools.partial(launch_cache.program, tag=repr(cfg), compiler_options=options,
                              out_shardings=seeds if split else None)
    if jax.process_count() > 1 or (s_init := store("init", init, (keys, hparams))) is None:
        return (*jitted, None)
    carry = shaped(s_init.eval_shape(keys, hparams))
    episode, called = jax.ShapeDtypeStruct((), jnp.int32), (carry, keys)
    if not split:  # as the calls will see them: the run's mesh, the carry replicated on it
        on = lambda spec: lambda x: jax.ShapeDtypeStruct(  # noqa: E731
            x.shape, x.dtype, sharding=jax.sharding.NamedSharding(seeds.mesh, spec))
        called = (jax.tree.map(on(jax.sharding.PartitionSpec()), carry),
                  jax.tree.map(on(seeds.spec), keys))
    # Each compiles (or loads) in the background once exported: the chunk's compile overlaps
    # the evaluation's tracing, and both overlap init's load and run (a resume's: its restore).
    if (s_chunk := store("chunk", chunk, (carry, episode), donate_argnums=(0,))) is not None:
        s_chunk.prefetch(called[0], episode)
    if (s_eval := store("evaluate", evaluate, (carry, keys))) is not None:
        s_eval.prefetch(*called)
    return s_init, s_chunk or jitted[1], s_eval or jitted[2], called[0]


def metric_fields(cfg: TrainConfig) -> tuple[str, ...]:
    """Columns of ``cfg``'s ``metrics.csv``: step, seed, the swept fields, the columns of the
    metrics of the algo's ``evaluate`` and of its chunk (:func:`flrjax.metric_names.columns`
    of their outputs' names, from ``jax.eval_shape``: nothing is compiled), then the run's
    times (:data:`flrjax.metric_names.TIMES`)."""
    return _metric_fields(_shape_key(cfg))


@functools.cache
def _metric_fields(cfg: TrainConfig) -> tuple[str, ...]:
    init, chunk, evaluate = build(cfg)
    keys = jax.ShapeDtypeStruct((padded_runs(cfg), 2), jnp.uint32, sharding=shard_seeds(cfg))
    carry = init.eval_shape(keys)
    _, train_m = chunk.eval_shape(carry, jax.ShapeDtypeStruct((), jnp.int32))
    ev = evaluate.eval_shape(carry, keys)
    return ("step", "seed", *sweep_points(cfg)[0], *columns(ev), *columns(train_m), *TIMES)


def _number(x: np.ndarray) -> int | float:
    return int(x) if np.issubdtype(x.dtype, np.integer) else float(x)


def _mean_per_seed(metrics: dict) -> dict:
    """Chunk metrics ``[S, episodes]`` -> per-seed means ``[S]``."""
    with warnings.catch_warnings():  # a metric that is NaN all chunk (no data) stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return {k: np.nanmean(np.asarray(v).reshape(v.shape[0], -1), axis=1)
                for k, v in metrics.items()}


ProgressFn = Callable[[int, list[dict]], bool | None]
"""``progress_fn(step, rows)`` after each chunk: its env step per seed and metric rows (one
per run); returning True ends the run after that chunk (checkpointed as ``checkpoint_every``
says, e.g. when a target is reached)."""


def train(cfg: TrainConfig, *, progress: bool = True, resume: bool = False,
          max_chunks: int | None = None, time_limit: float | None = None,
          progress_fn: ProgressFn | None = None) -> list[dict]:
    """Run ``cfg``; returns the metric rows (also written to ``cfg.out``/metrics.csv).

    With ``cfg.out`` the whole carry is checkpointed (orbax) after every chunk, keeping the
    last two, its files written while the next chunk trains (:class:`checkpoint.Saver`);
    ``resume=True`` continues from the newest checkpoint in ``cfg.out`` and drops the metric
    rows written after it, so the rows come out as in an uninterrupted run.
    ``max_chunks`` stops after that many chunks of this call (tests). ``time_limit`` (seconds
    of this call) stops before a chunk that would likely end past it, judged by the last
    chunk's duration, and checkpoints there even with ``checkpoint_every=0``: a long run can
    span jobs of a cluster's time limit, each ``--resume``-ing the last. ``progress_fn``: see
    :data:`ProgressFn` (brax's ``progress_fn``, with a way to stop). SIGINT or SIGTERM (in the
    main thread) stops as the time limit does, after the chunk in flight, then raises
    :class:`flrjax.stops.Stopped`; a second one ends the process at once.

    Under ``jax.distributed`` (:mod:`flrjax.distributed`) every process calls this alike and
    gets the same rows; process 0 alone writes metrics.csv, shows progress and calls
    ``progress_fn``; a stop that one process decides (signal, time limit, ``progress_fn``)
    is every process's, after the same chunk.
    """
    saver = checkpoint.Saver(cfg.out) if cfg.out else contextlib.nullcontext()
    with stops.stop_on_signals() as signals, launch_cache.compile_log() as compiles, \
            saver as saver:
        return _train(cfg, progress, resume, max_chunks, time_limit, progress_fn, signals,
                      compiles, saver)


def _train(cfg: TrainConfig, progress: bool, resume: bool, max_chunks: int | None,
           time_limit: float | None, progress_fn: ProgressFn | None,
           signals: list[int], compiles: launch_cache.CompileLog,
           saver: checkpoint.Saver | None) -> list[dict]:
    validate(cfg)
    init, chunk, evaluate = build(cfg)
    check_memory(cfg)
    key = jax.random.PRNGKey(cfg.seed)
    seed_sharding = shard_seeds(cfg)
    fields = metric_fields(cfg)
    main = distributed.is_main()
    if cfg.out and not resume and main:
        metrics_io.prepare_out(cfg, fields)  # before compiling: refuses another run's directory
    eval_key = jax.random.fold_in(key, 1)
    points = sweep_points(cfg)
    n_chunks = cfg.steps // cfg.steps_per_chunk
    rows: list[dict] = []
    start = 0
    if resume:  # into the carry's shapes: no fresh carry computed only to be replaced
        start, carry, rows = checkpoint.restore(cfg, carry_shapes(cfg, init), fields)
    else:
        carry = init_carry(cfg, init, key)
    stop = n_chunks if max_chunks is None else min(n_chunks, start + max_chunks)
    bar = _progress(n_chunks, cfg, start) if progress and main else None
    t_call = time.perf_counter()
    interrupted = False
    t_start = t_call - (rows[-1]["wall_time"] if rows else 0.0)
    for i in range(start, stop):
        t0 = time.perf_counter()
        carry, metrics = chunk(carry, jnp.int32(i * cfg.episodes_per_chunk))
        jax.block_until_ready(metrics)  # the chunk's own seconds, apart from its evaluation's
        chunk_s = time.perf_counter() - t0
        ev = evaluate(carry, distributed.put(
            run_keys(cfg, jax.random.fold_in(eval_key, i)), seed_sharding))
        metrics, ev, finite = real_runs(cfg, (metrics, ev, params_finite(cfg.algo, carry)))
        dt = time.perf_counter() - t0
        # JAX's own compile events, not the calls' time: on a GPU a call also runs most of
        # its chunk before it returns (XLA's while loops read their condition on the host)
        compile_s = compiles.within(t0, t0 + dt)
        step = (i + 1) * cfg.steps_per_chunk
        _check_finite(metrics, finite, step, i, cfg)
        train_m, ev = columns(_mean_per_seed(metrics)), columns(ev)
        for s in range(cfg.runs):
            rows.append({
                "step": step, "seed": s % cfg.seeds, **points[s // cfg.seeds],
                **{k: _number(v[s]) for k, v in ev.items()},
                **{k: float(v[s]) for k, v in train_m.items()},
                "wall_time": time.perf_counter() - t_start,
                "env_steps_per_s": cfg.runs * cfg.steps_per_chunk / dt,
                "chunk_s": chunk_s, "eval_s": dt - chunk_s,
            })
        signum = signals[0] if signals else 0  # one that progress_fn sends is the next chunk's
        late = time_limit is not None and time.perf_counter() - t_call + dt > time_limit
        done = main and progress_fn is not None and bool(progress_fn(step, rows[-cfg.runs:]))
        signum, late, done = distributed.agree(signum, late, done)
        interrupted = bool(signum) and i + 1 < stop
        halt = interrupted or (late and i + 1 < stop)
        if cfg.out and main:
            metrics_io.append_rows(cfg.out, rows[-cfg.runs:], fields)
        if saver is not None and (halt or cfg.checkpoint_every and (
                (i + 1) % cfg.checkpoint_every == 0 or i + 1 == stop)):
            saver.save(i + 1, carry)  # by every process, each its own part
        if bar is not None:
            if i == start:
                _leave_out_compile(bar, compile_s, dt, compiles.summary())
            bar.set_postfix(success=f"{ev['success_rate'].mean():.2f}",
                            steps_per_s=f"{rows[-1]['env_steps_per_s']:,.0f}")
            bar.update(1)
        if halt or done:
            break
    if bar is not None:
        bar.close()
    if interrupted:
        raise stops.Stopped(signum, i + 1, cfg)
    return rows


def carry_bytes(cfg: TrainConfig) -> int:
    """Bytes of the whole training state of all runs, the padding runs' too (replay buffers
    dominate), from shapes alone: nothing is compiled or allocated."""
    init, _, _ = build(cfg)
    shapes = init.eval_shape(jax.ShapeDtypeStruct((padded_runs(cfg), 2), jnp.uint32))
    return sum(x.size * x.dtype.itemsize for x in jax.tree.leaves(shapes))


def _device_bytes() -> int | None:
    """Memory of one device: the accelerator's limit, or the host's RAM for the CPU."""
    stats = jax.local_devices()[0].memory_stats() or {}
    if "bytes_limit" in stats:
        return int(stats["bytes_limit"])
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(cfg: TrainConfig, available: int | None = None) -> int:
    """Refuse a run whose state cannot fit: the carry, split over the devices, plus a quarter
    for the step's working memory, against one device's memory. Returns the carry's bytes."""
    need = carry_bytes(cfg)
    per_device = need / num_devices(cfg) * 1.25
    available = _device_bytes() if available is None else available
    if available is not None and per_device > available:
        raise ConfigError(
            f"the run needs about {per_device / 2**30:.1f} GiB per device (training state "
            f"{need / 2**30:.1f} GiB over {num_devices(cfg)} device(s), mostly replay: "
            f"{_runs_text(cfg)} x {cfg.buffer_episodes} episodes) but a device has "
            f"{available / 2**30:.1f} GiB; lower --buffer-episodes or --seeds, or add devices")
    return need


def _runs_text(cfg: TrainConfig) -> str:
    """``10 runs`` or ``12 runs (10 and 2 padding)``."""
    pad = padded_runs(cfg) - cfg.runs
    return f"{cfg.runs + pad} runs" + (f" ({cfg.runs} and {pad} padding)" if pad else "")


def init_carry(cfg: TrainConfig, init: Callable, key: jax.Array):
    """Every run's initial training state (``init`` from :func:`build`), split along the
    run axis over the devices."""
    return init(distributed.put(run_keys(cfg, key), shard_seeds(cfg)))


def carry_shapes(cfg: TrainConfig, init: WithHparams):
    """:func:`init_carry`'s shapes and placement, without computing it."""
    keys = jax.ShapeDtypeStruct((padded_runs(cfg), 2), jnp.uint32, sharding=shard_seeds(cfg))
    return init.carry_shapes(keys)


class TrainingFault(RuntimeError):
    """A seed's losses or parameters went non-finite; the run stopped before saving it."""


@functools.partial(jax.jit, static_argnums=0)
def params_finite(algo: str, carry) -> jax.Array:
    """Per run ``[runs]``: are all parameters the method trains finite
    (:attr:`flrjax.algos.Method.params`)?"""
    leaves = jax.tree.leaves(algos.get(algo).params(carry))
    return jnp.stack([jnp.isfinite(x).reshape(x.shape[0], -1).all(1) for x in leaves]).all(0)


def _check_finite(metrics: dict, finite_params: np.ndarray, step: int, chunk: int,
                  cfg: TrainConfig) -> None:
    """Stop on the first seed with a non-finite parameter or learner's metric
    (:data:`flrjax.metric_names.LEARNERS`) in any episode of the chunk (``metrics``: the
    chunk's, ``[runs, episodes]``). Called before the chunk's rows and checkpoint are
    written, so both stay at the last good chunk."""
    finite = {k: np.isfinite(v).reshape(cfg.runs, -1).all(1) for k, v in metrics.items()
              if is_learner(k)}
    for r in range(cfg.runs):
        bad = [k for k, ok in finite.items() if not ok[r]]
        if not finite_params[r]:
            bad.append("parameters")
        if bad:
            point = point_name(sweep_points(cfg)[r // cfg.seeds])
            s = f"{r % cfg.seeds}" + (f", {point}" if point else "")
            where = (f"; the last good checkpoint (chunk {chunk}) is in "
                     f"{checkpoint.ckpt_dir(cfg.out)}"
                     if cfg.out and cfg.checkpoint_every and chunk else "")
            raise TrainingFault(f"seed {s}: non-finite {', '.join(bad)} in the chunk ending "
                                f"at env step {step}{where}")


def _leave_out_compile(bar, compile_s: float, chunk_s: float, launched: str = "") -> None:
    """Start ``bar``'s clock after the first chunk's compile (``compile_s``: JAX's seconds
    of tracing, lowering and compiling or loading during it), so that its rate and estimate
    of the time left follow the chunks' run time from the first chunk on, and say so, with
    ``launched`` (:meth:`launch_cache.CompileLog.summary`: the launch's compiles so far)."""
    bar.start_t += compile_s
    bar.last_print_t += compile_s
    bar.write(f"first chunk: {chunk_s:.0f} s, {compile_s:.0f} s of it tracing and compiling "
              "(or loading compiled programs); the bar's times leave it out"
              + (f"\n  compiles so far: {launched}" if launched else ""), file=bar.fp)


def _progress(n_chunks: int, cfg: TrainConfig, done: int = 0):
    from tqdm import tqdm

    return tqdm(total=n_chunks, initial=done, unit="chunk",
                desc=f"{cfg.algo} {cfg.env} x{cfg.runs} runs", file=sys.stderr,
                dynamic_ncols=True)
