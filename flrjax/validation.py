"""The checks of a run's config before anything is built: :func:`validate` raises a
:class:`~flrjax.options.ConfigError` naming the first bad flag, so that a bad run fails in one
line at launch, not inside a traced program."""

from __future__ import annotations

import jax
import numpy as np

from flrjax import algos, envs
from flrjax.agents import gc_td3
from flrjax.config import (
    TrainConfig,
    flags,
    make_env,
    not_here,
    point_name,
    run_flags,
    sweep_fields,
    sweep_points,
)
from flrjax.options import ConfigError, dashed, values


def validate(cfg: TrainConfig) -> None:
    """Raise :class:`ConfigError` naming the first bad field: the flags' own checks
    (:class:`flrjax.options.Flag`), the run's shape, then the method's
    (:attr:`flrjax.algos.Method.validate`)."""
    if cfg.env not in envs.names():
        raise ConfigError(f"unknown env {cfg.env!r}; valid: {', '.join(envs.names())}")
    if cfg.algo not in algos.names():
        raise ConfigError(f"unknown algo {cfg.algo!r}; valid: {', '.join(algos.names())}")
    for name, v in flags(cfg).items():
        if any(isinstance(x, float) and not np.isfinite(x) for x in values(v)):
            raise ConfigError(f"{dashed(name)} must be a finite number, got {v}")
    _validate_sweep(cfg)
    _validate_values(cfg)
    if cfg.devices is not None and jax.process_count() > 1 and cfg.devices != jax.device_count():
        raise ConfigError(f"--devices: a run over {jax.process_count()} processes uses every "
                          f"device of each ({jax.device_count()}); drop --devices")
    if cfg.devices is not None and not 1 <= cfg.devices <= jax.device_count():
        raise ConfigError(f"--devices must be in 1..{jax.device_count()} (the visible "
                          f"devices), got {cfg.devices}")
    if cfg.goal_radius is not None and not cfg.env.startswith("ant"):
        raise ConfigError("--goal-radius applies to the ant envs only")
    iters = cfg.num_envs * cfg.updates_per_step
    if cfg.updates_per_step <= 0 or abs(iters - round(iters)) > 1e-9:
        raise ConfigError(f"--updates-per-step x --num-envs must be a positive integer "
                          f"(updates per vectorised step), got {iters:g}")
    try:
        group, _ = gc_td3.schedule(cfg.updates_per_iter, gc_td3.TD3Config.actor_update_freq)
    except ValueError as e:
        raise ConfigError(f"--updates-per-step x --num-envs: {e}") from None
    if cfg.horizon % group:
        raise ConfigError(f"the episode length ({cfg.horizon}) must be a multiple of "
                          f"{group}: the actor updates once per {group} env steps")
    algos.get(cfg.algo).validate(cfg, sweep_points(cfg), make_env(cfg))
    if cfg.steps % cfg.steps_per_chunk:
        raise ConfigError(f"--steps ({cfg.steps}) must be a multiple of num_envs x episode "
                          f"length x episodes_per_chunk = {cfg.steps_per_chunk}")
    if cfg.buffer_episodes < cfg.num_envs:
        raise ConfigError(f"--buffer-episodes ({cfg.buffer_episodes}) must be >= --num-envs "
                          f"({cfg.num_envs})")
    if cfg.batch_size > cfg.buffer_episodes * cfg.horizon:
        raise ConfigError(f"--batch-size ({cfg.batch_size}) is larger than the replay buffer "
                          f"({cfg.buffer_episodes} episodes x {cfg.horizon} steps)")


def _all_values(cfg: TrainConfig, field: str) -> list:
    """Every value a field takes over the run's sweep points (an unset one: None)."""
    points = sweep_points(cfg)
    if field in points[0]:
        return [p[field] for p in points]
    return list(values(getattr(cfg, field)))


def _validate_values(cfg: TrainConfig) -> None:
    """Each flag's check and choices, on every value it takes (unset ones pass)."""
    for name, f in run_flags(cfg).items():
        vals = [v for v in _all_values(cfg, name) if v is not None]
        if f.choices is not None:
            bad = [v for v in vals if v not in f.choices]
            if bad:
                raise ConfigError(f"{dashed(name)} must be one of {', '.join(f.choices)}, "
                                  f"got {bad[0]!r}")
        if f.check is not None:
            ok, want = f.check
            bad = [v for v in vals if not ok(v)]
            if bad:
                raise ConfigError(f"{dashed(name)} must be {want}, got {bad[0]}")


def _validate_sweep(cfg: TrainConfig) -> None:
    """One way of sweeping (tuple flags or ``--sweep``), of distinct points, over flags the
    method takes."""
    mine = run_flags(cfg)
    tuples = [k for k, f in mine.items() if f.sweep is not None
              and isinstance(getattr(cfg, k), tuple)]
    if cfg.sweep is None:
        for k in tuples:
            v = getattr(cfg, k)
            if len(set(v)) != len(v):
                raise ConfigError(f"{dashed(k)}: a sweep needs distinct values, got {v}")
        return
    if tuples:
        raise ConfigError(f"--sweep lists every point: give {dashed(tuples[0])} one value "
                          "(the points' default) or put its values in --sweep")
    if not cfg.sweep:
        raise ConfigError("--sweep needs at least one point")
    sweepable = sweep_fields()
    for point in cfg.sweep:
        for k, v in point:
            if k not in sweepable:
                raise ConfigError(f"--sweep: {k!r} cannot be swept; sweepable: "
                                  f"{', '.join(sweepable)}")
            if k not in mine:
                raise ConfigError(not_here(k))
            if isinstance(v, float) and not np.isfinite(v):
                raise ConfigError(f"--sweep: {k} must be a finite number, got {v}")
    points = [tuple(p.items()) for p in sweep_points(cfg)]
    if len(set(points)) != len(points):
        raise ConfigError("--sweep: the points must differ, got "
                          + "; ".join(point_name(p) for p in sweep_points(cfg)))
