"""``python -m flrjax.train``: the scanned, seed-vmapped trainer.

A run is a host loop over *chunks*. A chunk is one jitted call: ``vmap`` over seeds of a
``lax.scan`` over ``episodes_per_chunk`` lockstep episodes, each a ``lax.scan`` over the
episode's env steps (act, store, update). Between chunks the host evaluates, writes
``metrics.csv``, shows progress and checkpoints; nothing inside a chunk touches the host.

    python -m flrjax.train --env ant3leg --seeds 5    # FLR+DHRL, the fast preset on a GPU
    python -m flrjax.train --env point4leg --seeds 2  # the quick preset on a CPU
    python -m flrjax.train --env ant4leg --seeds 5 --num-envs 16 --updates-per-step 0.0625
    python -m flrjax.train --env ant3leg --algo flr_dhrl --seeds 5 --flr-alpha 0.001,0.01,0.1

A comma-separated ``--flr-alpha``, ``--flr-eps``, ``--flr-next`` or ``--initial-episodes`` is
a *sweep*: every value (every combination, for several) trains ``--seeds`` seeds in the same
vmapped chunk, since these only scale, compare or select numbers inside it. ``--sweep`` lists
the points instead of crossing them, e.g. Fig. 5's ablations with DHRL (α = 0) in one run::

    python -m flrjax.train --env ant3leg --algo flr_dhrl --seeds 5 \
        --sweep "flr-alpha=0; flr-alpha=0.001; flr-alpha=0.01; flr-alpha=0.1; flr-eps=0.5"

Seed ``s`` of each point starts from the same key as seed ``s`` of a plain run, and each row
of ``metrics.csv`` names its point in columns of the swept fields.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import functools
import itertools
import json
import math
import os
import re
import shlex
import shutil
import sys
import time
import warnings
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import envs, metrics_io, rewards
from flrjax.agents import gc_td3
from flrjax.algos import dhrl, flat, higl, pig

ALGOS = {"flat": flat, "dhrl": dhrl, "flr_dhrl": dhrl, "pig": pig, "flr_pig": pig,
         "higl": higl}
GRAPH_ALGOS = ("dhrl", "flr_dhrl", "pig", "flr_pig", "higl")
_EVAL_FIELDS = ("success_rate", "final_goal_distance", "falls", "final_torso_z",
                "random_goal_success", "random_goal_distance")
#: Per algorithm: evaluation metrics beyond the common ones, then the training metrics.
_ALGO_FIELDS = {
    "flat": ((), ("critic_loss", "q", "actor_loss", "train_success", "physics_resets")),
    "dhrl": (("eval_path_length",),
             ("critic_loss", "q", "critic_g_loss", "actor_loss", "high_critic_loss", "high_q",
              "high_actor_loss", "path_length", "graph_nodes", "reach_reward_upright",
              "reach_reward_fallen", "reward_gap", "reach_frac", "reach_fallen_frac",
              "flr_no_candidate_frac", "train_success", "physics_resets")),
}
_ALGO_FIELDS["flr_dhrl"] = _ALGO_FIELDS["dhrl"]
_ALGO_FIELDS["higl"] = ((), (
    "critic_loss", "q", "actor_loss", "high_critic_loss", "high_q", "high_actor_loss",
    "landmark_loss", "adjacency_loss", "rnd_loss", "graph_nodes", "train_success",
    "physics_resets"))
_ALGO_FIELDS["pig"] = _ALGO_FIELDS["flr_pig"] = (
    ("eval_path_length", "eval_on_target_frac", "no_plan_success_rate", "no_plan_goal_distance"),
    ("critic_loss", "q", "critic_g_loss", "actor_loss", "imitation", "skip_prob", "planned_steps",
     "graph_nodes", "reach_reward_upright", "reach_reward_fallen", "reward_gap",
     "reach_frac", "reach_fallen_frac", "flr_no_candidate_frac", "train_success", "physics_resets"))


def metric_fields(algo: str) -> tuple[str, ...]:
    """Columns of ``metrics.csv`` for ``algo``: one row per seed and evaluation."""
    extra_eval, train_fields = _ALGO_FIELDS[algo]
    return ("step", "seed", *_EVAL_FIELDS, *extra_eval, *train_fields, "wall_time",
            "env_steps_per_s")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a run. ``steps`` counts env steps per seed (all envs)."""

    env: str = "point3leg"
    algo: str = "flr_dhrl"
    seeds: int = 1
    seed: int = 0
    steps: int = 20_000
    num_envs: int = 1
    # Gradient updates per env step; the paper protocol (the reference) is 1 with 1 env.
    updates_per_step: float = 1.0
    episodes_per_chunk: int = 5
    eval_episodes: int = 10
    batch_size: int = 1024
    hidden: int = 256
    # Target networks: Polyak factor and period in updates (reference: 0.995 every 10 updates).
    polyak: float = 0.995
    target_update_freq: int = 10
    buffer_episodes: int = 2500  # replay capacity per seed (1.5M transitions at T = 600)
    initial_episodes: int | tuple[int, ...] = 10  # a tuple sweeps it (SWEEP_FIELDS)
    episode_length: int | None = None  # env override; None = the env's own
    goal_radius: float | None = None  # ant env override: training goals within this of start
    # DHRL (--algo dhrl); None = the env's default (DHRL_ENV_DEFAULTS)
    subgoal_freq: int | None = None  # env steps per subgoal (reference: 40)
    graph_start_steps: int | None = None  # env steps per seed before the first graph
    graph_every_steps: int | None = None  # env steps per seed between graph rebuilds
    cutoff: float | None = None  # max edge length, in estimated steps (reference: 30)
    landmark_eps: float | None = None  # FPS early-stop distance (reference: 10)
    max_landmarks: int | None = None  # at most this many graph nodes (reference: 300)
    landmark_sample: int | None = None  # replay states FPS picks from (reference: 6000)
    # FLR (--algo flr_*); None = the paper's value (FLR_DEFAULTS)
    # A tuple of values sweeps the field inside one vmapped run (see SWEEP_FIELDS).
    flr_alpha: float | tuple[float, ...] | None = None  # eq. (5); the paper: 0.01 = 1 - gamma
    flr_eps: float | tuple[float, ...] | None = None  # next subgoals at >= eps; the paper: 2
    flr_next: str | tuple[str, ...] | None = None  # "sample" (ring at eps) or "goal" (Fig. 5)
    flr_candidates: int | None = None  # next subgoals sampled per transition
    # Reaching transitions per V evaluation (dhrl.FLRConfig.value_chunk), 0 = all at once;
    # None = FLR_GPU_DEFAULTS on a GPU, FLRConfig's 128 elsewhere. It shapes the compiled
    # step, so it is never swept, and it does not change the rewards (up to float).
    flr_value_chunk: int | None = None
    # Matrix operands of eq. 5's candidate values (dhrl.FLRConfig.value_dtype), "float32" or
    # "bfloat16"; None = FLR_GPU_DEFAULTS on a GPU, float32 elsewhere. Never swept.
    flr_precision: str | None = None
    # PIG's subgoal skipping (--algo pig|flr_pig): each hop past a waypoint with probability
    # jump_temp / imitation loss; None = the reference's (PIG_DEFAULTS); 0 turns it off
    pig_jump_temp: float | tuple[float, ...] | None = None
    # Explicit sweep points (--sweep), each ((field, value), ...); a field a point leaves out
    # keeps the run's value. Exclusive with tuple-valued fields.
    sweep: tuple[tuple[tuple[str, float | int | str], ...], ...] | None = None
    out: str | None = None
    checkpoint_every: int = 1  # chunks between checkpoints in OUT/checkpoints; 0: none
    # Devices the seed axis is sharded over; None: as many of the visible ones as divide seeds
    devices: int | None = None

    @property
    def horizon(self) -> int:
        return self.episode_length or _default_episode_length(self.env)

    @property
    def steps_per_chunk(self) -> int:
        return self.num_envs * self.horizon * self.episodes_per_chunk

    @property
    def updates_per_iter(self) -> int:
        return round(self.num_envs * self.updates_per_step)

    @property
    def runs(self) -> int:
        """Runs trained at once (the vmapped axis): seeds x sweep points."""
        return self.seeds * len(sweep_points(self))


#: Fields that may hold a tuple of values, swept inside one vmapped run: they are numbers the
#: step only multiplies, compares or selects with, so every value shares the compiled chunk.
#: (A swept ``initial_episodes`` makes the random phase a per-run choice: both of its branches
#: run every step and each run keeps its own, so the random rounds cost as much as learning.
#: ``flr_next`` becomes a per-run choice between the two candidate sets, both drawn.)
SWEEP_FIELDS = ("flr_alpha", "flr_eps", "flr_next", "initial_episodes", "pig_jump_temp")
PIG_ALGOS = ("pig", "flr_pig")


def sweep_points(cfg: TrainConfig) -> list[dict[str, float | int | str]]:
    """The swept values of each point, in run order: ``cfg.sweep``'s points (each completed
    with the run's values of the fields other points set), or the product of the swept
    fields' values, the last field fastest; ``[{}]`` when nothing is swept. Run ``r`` is seed
    ``r % cfg.seeds`` of point ``r // cfg.seeds``."""
    if cfg.sweep is not None:
        keys = [k for k in SWEEP_FIELDS if any(k in dict(p) for p in cfg.sweep)]
        return [{k: dict(p)[k] if k in dict(p) else _run_value(cfg, k) for k in keys}
                for p in cfg.sweep]
    swept = [k for k in SWEEP_FIELDS if isinstance(getattr(cfg, k), tuple)]
    return [dict(zip(swept, vals, strict=True))
            for vals in itertools.product(*(getattr(cfg, k) for k in swept))]


def _run_value(cfg: TrainConfig, field: str) -> float | int | str:
    """A sweepable field's single value in ``cfg`` (the paper's for an unset ``flr_*``, the
    reference's for an unset ``pig_*``)."""
    v = getattr(cfg, field)
    return {**FLR_DEFAULTS, **PIG_DEFAULTS}[field] if v is None else v


def point_name(point: dict) -> str:
    """``flr_alpha 0.01, flr_next goal``: a sweep point for messages."""
    return ", ".join(f"{k} {v}" if isinstance(v, str) else f"{k} {v:g}"
                     for k, v in point.items())


def csv_fields(cfg: TrainConfig) -> tuple[str, ...]:
    """Columns of ``cfg``'s ``metrics.csv``: :func:`metric_fields`, with the swept fields
    after ``seed``."""
    step, seed, *rest = metric_fields(cfg.algo)
    return (step, seed, *sweep_points(cfg)[0], *rest)


@functools.cache
def _default_episode_length(env: str) -> int:
    """The env's own episode length (building an env compiles its MJCF: do it once)."""
    return envs.make(env).config.episode_length


PRESETS: dict[str, dict] = {
    # A CPU run of about two minutes on a point mass that shows learning: success starts at 0
    # and rises within a few thousand steps, seen through an evaluation every 800 steps
    # (the default method, FLR+DHRL, in the room: one of two seeds at 1.0 by 2.4k steps, both
    # by 6.4k). Small networks and batches; targets follow every update (0.99), as suits a
    # run this short (the reference's 0.995 every 10 updates suits a million steps).
    "quick": dict(steps=9_600, num_envs=4, updates_per_step=1.0, episodes_per_chunk=2,
                  batch_size=256, hidden=64, buffer_episodes=400, initial_episodes=8,
                  polyak=0.99, target_update_freq=1),
    # The reference's scale: 3x256 networks, batch 1024, one update per env step.
    "paper": dict(steps=1_200_000, num_envs=1, updates_per_step=1.0, episodes_per_chunk=5,
                  batch_size=1024, hidden=256, buffer_episodes=2500, initial_episodes=10,
                  polyak=0.995, target_update_freq=10),
    # The reference's networks on 16 lockstep envs per seed with an update every 4 env steps
    # and DHRL's 200 random episodes rounded to the envs (192): the protocol of every GPU
    # figure in docs/results.md, where FLR+DHRL reaches the tripod's goal.
    "fast": dict(steps=1_920_000, num_envs=16, updates_per_step=0.25, episodes_per_chunk=5,
                 batch_size=1024, hidden=256, buffer_episodes=2500, initial_episodes=192,
                 polyak=0.995, target_update_freq=10),
}


class ConfigError(ValueError):
    """A bad flag or combination of flags; shown as one line, without a traceback."""


def validate(cfg: TrainConfig) -> None:
    """Raise :class:`ConfigError` naming the first bad field."""
    if cfg.env not in envs.names():
        raise ConfigError(f"unknown env {cfg.env!r}; valid: {', '.join(envs.names())}")
    if cfg.algo not in ALGOS:
        raise ConfigError(f"unknown algo {cfg.algo!r}; valid: {', '.join(ALGOS)}")
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if any(isinstance(x, float) and not np.isfinite(x) for x in _values(v)):
            raise ConfigError(f"--{f.name.replace('_', '-')} must be a finite number, got {v}")
    _validate_sweep(cfg)
    for name in ("seeds", "steps", "num_envs", "episodes_per_chunk", "eval_episodes",
                 "batch_size", "hidden", "buffer_episodes", "target_update_freq"):
        if getattr(cfg, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be >= 1, got "
                              f"{getattr(cfg, name)}")
    if not 0.0 <= cfg.polyak < 1.0:
        raise ConfigError(f"--polyak must be in [0, 1), got {cfg.polyak}")
    if cfg.devices is not None and not (1 <= cfg.devices <= jax.device_count()
                                        and cfg.runs % cfg.devices == 0):
        raise ConfigError(f"--devices must divide the runs (--seeds x sweep values: "
                          f"{cfg.runs}) and be in 1..{jax.device_count()} (the visible "
                          f"devices), got {cfg.devices}")
    if cfg.checkpoint_every < 0:
        raise ConfigError(f"--checkpoint-every must be >= 0, got {cfg.checkpoint_every}")
    if min(_all_values(cfg, "initial_episodes")) < 0:
        raise ConfigError(f"--initial-episodes must be >= 0, got "
                          f"{min(_all_values(cfg, 'initial_episodes'))}")
    if cfg.goal_radius is not None and not cfg.env.startswith("ant"):
        raise ConfigError("--goal-radius applies to the ant envs only")
    if cfg.goal_radius is not None and cfg.goal_radius <= 0:
        raise ConfigError(f"--goal-radius must be > 0, got {cfg.goal_radius}")
    if cfg.episode_length is not None and cfg.episode_length < 2:
        raise ConfigError(f"--episode-length must be >= 2, got {cfg.episode_length}")
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
    dhrl_flags = [k for k in DHRL_FIELDS if getattr(cfg, k) is not None]
    if cfg.algo not in GRAPH_ALGOS and dhrl_flags:
        raise ConfigError(f"--{dhrl_flags[0].replace('_', '-')} applies to the graph algos "
                          f"({', '.join(GRAPH_ALGOS)}) only")
    if cfg.algo in GRAPH_ALGOS:
        _validate_dhrl(cfg, group)
    flr_flags = [k for k in FLR_FIELDS if getattr(cfg, k) is not None]
    if not cfg.algo.startswith("flr_") and flr_flags:
        raise ConfigError(f"--{flr_flags[0].replace('_', '-')} applies to the flr_* algos only")
    if cfg.algo.startswith("flr_"):
        _validate_flr(cfg)
    if cfg.pig_jump_temp is not None or "pig_jump_temp" in sweep_points(cfg)[0]:
        if cfg.algo not in PIG_ALGOS:
            raise ConfigError(f"--pig-jump-temp applies to {' and '.join(PIG_ALGOS)} only")
        if min(_all_values(cfg, "pig_jump_temp")) < 0:
            raise ConfigError(f"--pig-jump-temp must be >= 0, got "
                              f"{min(_all_values(cfg, 'pig_jump_temp'))}")
    if cfg.steps % cfg.steps_per_chunk:
        raise ConfigError(f"--steps ({cfg.steps}) must be a multiple of num_envs x episode "
                          f"length x episodes_per_chunk = {cfg.steps_per_chunk}")
    if cfg.buffer_episodes < cfg.num_envs:
        raise ConfigError(f"--buffer-episodes ({cfg.buffer_episodes}) must be >= --num-envs "
                          f"({cfg.num_envs})")
    if cfg.batch_size > cfg.buffer_episodes * cfg.horizon:
        raise ConfigError(f"--batch-size ({cfg.batch_size}) is larger than the replay buffer "
                          f"({cfg.buffer_episodes} episodes x {cfg.horizon} steps)")


DHRL_FIELDS = ("subgoal_freq", "graph_start_steps", "graph_every_steps", "cutoff",
               "landmark_eps", "max_landmarks", "landmark_sample")


def _validate_dhrl(cfg: TrainConfig, group: int) -> None:
    d = dhrl_settings(cfg)
    for name in ("subgoal_freq", "graph_every_steps", "max_landmarks", "landmark_sample"):
        if d[name] < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be >= 1, got {d[name]}")
    for name in ("cutoff", "landmark_eps"):
        if d[name] <= 0:
            raise ConfigError(f"--{name.replace('_', '-')} must be > 0, got {d[name]}")
    if d["graph_start_steps"] < 0:
        raise ConfigError(f"--graph-start-steps must be >= 0, got {d['graph_start_steps']}")
    if cfg.horizon % d["subgoal_freq"] or d["subgoal_freq"] % group:
        raise ConfigError(f"--subgoal-freq ({d['subgoal_freq']}) must divide the episode "
                          f"length ({cfg.horizon}) and be a multiple of {group} (the actor "
                          f"updates once per {group} env steps)")
    if d["max_landmarks"] > d["landmark_sample"]:
        raise ConfigError(f"--max-landmarks ({d['max_landmarks']}) must be <= "
                          f"--landmark-sample ({d['landmark_sample']})")


def _values(v):
    """A field's values: its tuple (a sweep), or the one value."""
    return v if isinstance(v, tuple) else (v,)


def _all_values(cfg: TrainConfig, field: str) -> list:
    """Every value a sweepable field takes over the run's sweep points."""
    points = sweep_points(cfg)
    if field in points[0]:
        return [p[field] for p in points]
    return list(_values(getattr(cfg, field)))


def _validate_sweep(cfg: TrainConfig) -> None:
    tuples = [k for k in SWEEP_FIELDS if isinstance(getattr(cfg, k), tuple)]
    if cfg.sweep is not None:
        if tuples:
            raise ConfigError(f"--sweep lists every point: give --{tuples[0].replace('_', '-')} "
                              "one value (the points' default) or put its values in --sweep")
        if not cfg.sweep:
            raise ConfigError("--sweep needs at least one point")
        for point in cfg.sweep:
            for k, v in point:
                if k not in SWEEP_FIELDS:
                    raise ConfigError(f"--sweep: {k!r} cannot be swept; sweepable: "
                                      f"{', '.join(SWEEP_FIELDS)}")
                if isinstance(v, float) and not np.isfinite(v):
                    raise ConfigError(f"--sweep: {k} must be a finite number, got {v}")
        points = [tuple(p.items()) for p in sweep_points(cfg)]
        if len(set(points)) != len(points):
            raise ConfigError("--sweep: the points must differ, got "
                              + "; ".join(point_name(p) for p in sweep_points(cfg)))
        tuples = list(sweep_points(cfg)[0])
    for k in tuples:
        flag = "--" + k.replace("_", "-")
        if k.startswith("flr_") and not cfg.algo.startswith("flr_"):
            raise ConfigError(f"{flag} applies to the flr_* algos only")
        v = getattr(cfg, k)
        if cfg.sweep is None and len(set(v)) != len(v):
            raise ConfigError(f"{flag}: a sweep needs distinct values, got {v}")
    if isinstance(cfg.flr_eps, tuple) and "goal" in _values(cfg.flr_next):
        raise ConfigError("--flr-eps: a sweep over eps means nothing with --flr-next goal "
                          "(the final goal is the only candidate); list the points with "
                          "--sweep")


def _validate_flr(cfg: TrainConfig) -> None:
    for point in sweep_points(cfg):
        _validate_flr_values(dataclasses.replace(cfg, **point))


def _validate_flr_values(cfg: TrainConfig) -> None:
    f = flr_config(cfg)
    if f.next_subgoal not in ("sample", "goal"):
        raise ConfigError(f"--flr-next must be 'sample' or 'goal', got {f.next_subgoal!r}")
    if f.num_candidates < 1:
        raise ConfigError(f"--flr-candidates must be >= 1, got {f.num_candidates}")
    if cfg.flr_precision not in (None, *FLR_PRECISIONS):
        raise ConfigError(f"--flr-precision must be one of {', '.join(FLR_PRECISIONS)}, got "
                          f"{cfg.flr_precision!r}")
    if cfg.flr_value_chunk is not None and cfg.flr_value_chunk < 0:
        raise ConfigError(f"--flr-value-chunk must be >= 0 (0: the whole batch), got "
                          f"{cfg.flr_value_chunk}")
    try:
        rewards.validate_flr_params(f.alpha, gc_td3.TD3Config.gamma,
                                    None if f.next_subgoal == "goal" else f.eps,
                                    make_env(cfg).config.delta)
    except ValueError as e:
        raise ConfigError(f"--flr-alpha / --flr-eps: {e}") from None


def make_env(cfg: TrainConfig):
    extra = {k: v for k in ("episode_length", "goal_radius")
             if (v := getattr(cfg, k)) is not None}
    return envs.make(cfg.env, **extra)


def td3_config(cfg: TrainConfig) -> gc_td3.TD3Config:
    return gc_td3.TD3Config(hidden_sizes=(cfg.hidden,) * 3, batch_size=cfg.batch_size,
                            polyak=cfg.polyak, target_update_freq=cfg.target_update_freq)


def flat_config(cfg: TrainConfig) -> flat.FlatConfig:
    return flat.FlatConfig(num_envs=cfg.num_envs, updates_per_iter=cfg.updates_per_iter,
                           buffer_episodes=cfg.buffer_episodes,
                           initial_episodes=cfg.initial_episodes,
                           eval_episodes=cfg.eval_episodes, delta=make_env(cfg).config.delta,
                           td3=td3_config(cfg))


#: DHRL settings per env family. The ant: the reference's AntMaze run (AntMaze.sh). The point
#: mass moves up to 1 unit per step, 5-10x the ant's pace, and its episodes are 100 steps: its
#: distances in steps, time windows and graph sizes are scaled down to match.
DHRL_ENV_DEFAULTS: dict[str, dict] = {
    "ant": dict(subgoal_freq=40, graph_start_steps=dhrl.REFERENCE_GRAPH_START_STEPS,
                graph_every_steps=dhrl.REFERENCE_EPOCH_STEPS, cutoff=30.0, landmark_eps=10.0,
                max_landmarks=300, landmark_sample=6000, low_future_step=150),
    "point": dict(subgoal_freq=10, graph_start_steps=2_000, graph_every_steps=800, cutoff=6.0,
                  landmark_eps=3.0, max_landmarks=64, landmark_sample=1000, low_future_step=25),
}


def dhrl_settings(cfg: TrainConfig) -> dict:
    """The DHRL fields of ``cfg`` with the env's defaults filled in."""
    base = DHRL_ENV_DEFAULTS["ant" if cfg.env.startswith("ant") else "point"]
    return {k: (v if getattr(cfg, k, None) is None else getattr(cfg, k)) for k, v in base.items()}


def dhrl_config(cfg: TrainConfig) -> dhrl.DHRLConfig:
    d = dhrl_settings(cfg)
    env = make_env(cfg)
    per_round = cfg.num_envs * cfg.horizon
    low = dataclasses.replace(td3_config(cfg), future_step=d["low_future_step"])
    high = dhrl.high_config(low, env.maze.bounds,
                            future_step=cfg.horizon // d["subgoal_freq"])
    return dhrl.DHRLConfig(
        num_envs=cfg.num_envs, updates_per_iter=cfg.updates_per_iter,
        buffer_episodes=cfg.buffer_episodes, initial_episodes=cfg.initial_episodes,
        eval_episodes=cfg.eval_episodes, delta=env.config.delta, low=low, high=high,
        subgoal_freq=d["subgoal_freq"], initial_sample=d["landmark_sample"],
        max_nodes=d["max_landmarks"], stop_eps=d["landmark_eps"], cutoff=d["cutoff"],
        graph_start_round=-(-d["graph_start_steps"] // per_round),
        graph_every=max(1, round(d["graph_every_steps"] / per_round)))


#: The paper's FLR settings (§3.1): alpha 0.01, eps 2; 16 candidates is ours (the paper
#: samples "several").
FLR_DEFAULTS = dict(flr_alpha=0.01, flr_eps=2.0, flr_next="sample", flr_candidates=16)
#: The flr_* fields. ``flr_value_chunk`` has no entry in FLR_DEFAULTS: it is no point's value
#: (experiments/run_grid.py fills FLR_DEFAULTS into saved configs to compare sweep points) and
#: its None means FLRConfig's own default.
FLR_FIELDS = (*FLR_DEFAULTS, "flr_value_chunk", "flr_precision")
#: --flr-precision's choices (dhrl.FLRConfig.value_dtype).
FLR_PRECISIONS = ("float32", "bfloat16")
#: How the trainer evaluates eq. 5's candidate values on a GPU, unless flags say otherwise:
#: the whole batch in one call (fewer, larger matrix products) with bf16 matrix operands
#: (float32 accumulation and parameters: twice the tensor cores' rate). The reward is a max
#: over randomly drawn candidates; bf16 moves it by a fraction of what a new draw of the
#: candidates does (tests/algos/test_dhrl.py, docs/benchmarks.md). Elsewhere FLRConfig's
#: own: float32, the reaching transitions only, in chunks (on a CPU the FLOPs count).
FLR_GPU_DEFAULTS = dict(flr_value_chunk=0, flr_precision="bfloat16")
#: PIG's settings that flags change (pig.PIGConfig has the reference's values and sources).
PIG_DEFAULTS = dict(pig_jump_temp=pig.PIGConfig.jump_temp)


def flr_config(cfg: TrainConfig) -> dhrl.FLRConfig | None:
    """The FLR settings of an ``flr_*`` algo (None for the others)."""
    if not cfg.algo.startswith("flr_"):
        return None
    d = {k: (FLR_DEFAULTS[k] if getattr(cfg, k) is None else getattr(cfg, k))
         for k in FLR_DEFAULTS}
    gpu = FLR_GPU_DEFAULTS if jax.default_backend() == "gpu" else {}
    chunk, precision = (gpu.get(k) if getattr(cfg, k) is None else getattr(cfg, k)
                        for k in ("flr_value_chunk", "flr_precision"))
    extra = {} if chunk is None else {"value_chunk": chunk or None}
    if precision is not None:
        extra["value_dtype"] = precision
    return dhrl.FLRConfig(alpha=d["flr_alpha"], eps=d["flr_eps"],
                          num_candidates=d["flr_candidates"], next_subgoal=d["flr_next"],
                          **extra)


#: PIG's imitation weight: train_antmaze.sh --lambda_goal_loss 0.001 on torques of +-30,
#: i.e. 0.001 * 30**2 on our actions in [-1, 1].
PIG_IMITATION_WEIGHT = 0.001 * 30.0**2


def higl_config(cfg: TrainConfig) -> higl.HIGLConfig:
    """HIGL (higl_ant_maze_u.sh / main.py): subgoals relative to the position every 10 steps
    (5 on the point mass) within the maze's half extent, manager noise 1 and target noise 0.2,
    controller discount 0.95 with the dense reward, plain Q critics (no distance
    parametrisation), no HER, graph edges under 38 (``--clip_v``)."""
    given = {k: getattr(cfg, k) for k in ("subgoal_freq", "cutoff") if getattr(cfg, k)}
    point = not cfg.env.startswith("ant")
    c = dataclasses.replace(cfg, **{"subgoal_freq": 5 if point else 10, "cutoff": 38.0,
                                    **given})
    base = dhrl_config(c)
    lo, hi = make_env(cfg).maze.bounds
    scale = tuple(float(h - lo_) / 2 for lo_, h in zip(lo, hi, strict=True))
    low = dataclasses.replace(base.low, gamma=0.95, dist_critic=False, clip_return=1e6,
                              future_p=0.0)
    high = dataclasses.replace(base.high, action_max=scale, action_offset=(0.0, 0.0),
                               noise_eps=1.0 / max(scale), target_noise=0.2,
                               dist_critic=False, clip_return=1e6, future_p=0.0)
    return higl.HIGLConfig(base=dataclasses.replace(base, low=low, high=high))


#: TrainConfig's swept FLR fields -> their names in :class:`dhrl.FLRConfig`.
_FLR_CONFIG_NAMES = {"flr_alpha": "alpha", "flr_eps": "eps", "flr_next": "next_subgoal"}


def _sweep_column(field: str, vals: list) -> np.ndarray:
    """One swept field's per-point values as the array vmapped over runs (``flr_next``: a
    bool, True for the goal)."""
    if field == "flr_next":
        return np.array([v == "goal" for v in vals])
    return np.array(vals, np.int32 if isinstance(vals[0], int) else np.float32)


def with_values(acfg, values: dict):
    """``acfg`` (any algo's config) with ``values``, the traced :data:`SWEEP_FIELDS` of one
    run of a sweep, in their places (``flr_*`` in its FLR settings)."""
    if not values:
        return acfg
    if isinstance(acfg, pig.PIGConfig | higl.HIGLConfig):  # a DHRL config inside
        own = {k.removeprefix("pig_"): v for k, v in values.items() if k.startswith("pig_")}
        rest = {k: v for k, v in values.items() if not k.startswith("pig_")}
        return dataclasses.replace(acfg, base=with_values(acfg.base, rest), **own)
    flr_kw = {_FLR_CONFIG_NAMES[k]: v for k, v in values.items() if k.startswith("flr_")}
    if flr_kw:
        acfg = dataclasses.replace(acfg, flr=dataclasses.replace(acfg.flr, **flr_kw))
    return dataclasses.replace(acfg, **{k: v for k, v in values.items()
                                        if not k.startswith("flr_")})


def algo_config(cfg: TrainConfig):
    """The algo's own config (of one sweep point: :func:`_build` puts each run's values in)."""
    cfg = dataclasses.replace(cfg, **sweep_points(cfg)[0])
    if cfg.algo == "higl":
        return higl_config(cfg)
    if cfg.algo in ("dhrl", "flr_dhrl"):
        return dataclasses.replace(dhrl_config(cfg), flr=flr_config(cfg))
    if cfg.algo in PIG_ALGOS:
        base = dhrl_config(cfg)
        low = dataclasses.replace(base.low, imitation_weight=PIG_IMITATION_WEIGHT)
        return pig.PIGConfig(base=dataclasses.replace(base, low=low, flr=flr_config(cfg)),
                             jump_temp=_run_value(cfg, "pig_jump_temp"))
    return flat_config(cfg)


def default_compile_cache() -> str:
    """Where compiled programs persist between runs: ``$JAX_COMPILATION_CACHE_DIR`` if set,
    else ``flrjax/jax`` in the user's cache directory (``$XDG_CACHE_HOME`` or ``~/.cache``)."""
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return os.environ["JAX_COMPILATION_CACHE_DIR"]
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(root, "flrjax", "jax")


def enable_compile_cache(path: str | None) -> None:
    """Keep compiled programs in ``path`` (None: the cache stays as JAX has it), so that a
    second launch of the same config loads its chunk instead of compiling it again."""
    if path is None:
        return
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def build(cfg: TrainConfig) -> tuple[Callable, Callable, Callable]:
    """(init(keys[S]), chunk(carry[S], first_episode), evaluate(carry[S], keys[S])), jitted.

    Cached on the fields that shape the computation, so runs that differ only in seed, length
    or output directory reuse the compiled chunk.
    """
    return _build(dataclasses.replace(cfg, out=None, seed=0, steps=cfg.steps_per_chunk))


@functools.cache
def _build(cfg: TrainConfig) -> tuple[Callable, Callable, Callable]:
    env, acfg, algo = make_env(cfg), algo_config(cfg), ALGOS[cfg.algo]
    # Each run's swept values (run r: point r // seeds), vmapped alongside the carry.
    points = sweep_points(cfg)
    values = {k: np.repeat(_sweep_column(k, [p[k] for p in points]), cfg.seeds)
              for k in points[0]}

    def chunk(carry, first_episode):
        episodes = first_episode + jnp.arange(cfg.episodes_per_chunk)

        def one_run(c, v):
            run_cfg = with_values(acfg, v)
            return jax.lax.scan(lambda c, e: algo.train_episode(c, e, env, run_cfg), c,
                                episodes)

        return jax.vmap(one_run)(carry, values)

    # Every output split along the seed axis over the devices, as the inputs are: left to
    # itself, XLA may lay out some leaves otherwise (replicated, or with another spec), and
    # the next chunk would recompile for the changed input layout.
    seeds = shard_seeds(cfg)
    init = jax.jit(jax.vmap(lambda k: algo.init(k, env, acfg)), out_shardings=seeds)

    def evaluate(carry, keys):  # with each run's values too: some act at test time (PIG's)
        return jax.vmap(lambda c, k, v: algo.evaluate(c, k, env, with_values(acfg, v)))(
            carry, keys, values)

    return (init, jax.jit(chunk, donate_argnums=0, out_shardings=seeds),
            jax.jit(evaluate, out_shardings=seeds))


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
    last two; ``resume=True`` continues from the newest checkpoint in ``cfg.out`` and drops the
    metric rows written after it, so the rows come out as in an uninterrupted run.
    ``max_chunks`` stops after that many chunks of this call (tests). ``time_limit`` (seconds
    of this call) stops before a chunk that would likely end past it, judged by the last
    chunk's duration, and checkpoints there even with ``checkpoint_every=0``: a long run can
    span jobs of a cluster's time limit, each ``--resume``-ing the last. ``progress_fn``: see
    :data:`ProgressFn` (brax's ``progress_fn``, with a way to stop).
    """
    validate(cfg)
    init, chunk, evaluate = build(cfg)
    check_memory(cfg)
    key = jax.random.PRNGKey(cfg.seed)
    seed_sharding = shard_seeds(cfg)
    if cfg.out and not resume:
        prepare_out(cfg)  # before compiling: refuses a directory holding another run
    carry = init_carry(cfg, init, key)
    eval_key = jax.random.fold_in(key, 1)
    points = sweep_points(cfg)
    n_chunks = cfg.steps // cfg.steps_per_chunk
    rows: list[dict] = []
    start = 0
    if resume:
        start, carry, rows = _restore(cfg, carry)
    stop = n_chunks if max_chunks is None else min(n_chunks, start + max_chunks)
    bar = _progress(n_chunks, cfg, start) if progress else None
    t_call = time.perf_counter()
    t_start = t_call - (rows[-1]["wall_time"] if rows else 0.0)
    for i in range(start, stop):
        t0 = time.perf_counter()
        carry, metrics = chunk(carry, jnp.int32(i * cfg.episodes_per_chunk))
        ev = evaluate(carry, jax.device_put(
            run_keys(cfg, jax.random.fold_in(eval_key, i)), seed_sharding))
        train_m, ev = _mean_per_seed(metrics), jax.tree.map(np.asarray, ev)
        dt = time.perf_counter() - t0
        step = (i + 1) * cfg.steps_per_chunk
        _check_finite(train_m, np.asarray(params_finite(carry)), step, i, cfg)
        extra_eval, train_fields = _ALGO_FIELDS[cfg.algo]
        for s in range(cfg.runs):
            rows.append({
                "step": step, "seed": s % cfg.seeds, **points[s // cfg.seeds],
                **{k: float(ev[k][s]) for k in (*_EVAL_FIELDS, *extra_eval)},
                "falls": int(ev["falls"][s]),
                **{k: float(train_m[k][s]) for k in train_fields},
                "wall_time": time.perf_counter() - t_start,
                "env_steps_per_s": cfg.runs * cfg.steps_per_chunk / dt,
            })
        out_of_time = (time_limit is not None and i + 1 < stop
                       and time.perf_counter() - t_call + dt > time_limit)
        done = progress_fn is not None and bool(progress_fn(step, rows[-cfg.runs:]))
        if cfg.out:
            _append_rows(cfg.out, rows[-cfg.runs:], csv_fields(cfg))
            if out_of_time or cfg.checkpoint_every and (
                    (i + 1) % cfg.checkpoint_every == 0 or i + 1 == stop):
                _save(cfg.out, i + 1, carry)
        if bar is not None:
            bar.set_postfix(success=f"{ev['success_rate'].mean():.2f}",
                            steps_per_s=f"{rows[-1]['env_steps_per_s']:,.0f}")
            bar.update(1)
        if out_of_time or done:
            break
    if bar is not None:
        bar.close()
    return rows


def carry_bytes(cfg: TrainConfig) -> int:
    """Bytes of the whole training state of all seeds (replay buffers dominate), from shapes
    alone: nothing is compiled or allocated."""
    init, _, _ = build(cfg)
    shapes = jax.eval_shape(init, jax.ShapeDtypeStruct((cfg.runs, 2), jnp.uint32))
    return sum(x.size * x.dtype.itemsize for x in jax.tree.leaves(shapes))


def _device_bytes() -> int | None:
    """Memory of one device: the accelerator's limit, or the host's RAM for the CPU."""
    stats = jax.devices()[0].memory_stats() or {}
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
            f"{cfg.runs} runs x {cfg.buffer_episodes} episodes) but a device has "
            f"{available / 2**30:.1f} GiB; lower --buffer-episodes or --seeds, or add devices")
    return need


def num_devices(cfg: TrainConfig) -> int:
    """How many devices the seeds are split over: ``cfg.devices``, or the most of the visible
    devices that divides ``cfg.runs`` (seeds x sweep points)."""
    if cfg.devices is not None:
        return cfg.devices
    n = jax.device_count()
    return max(d for d in range(1, n + 1) if cfg.runs % d == 0)


def shard_seeds(cfg: TrainConfig) -> jax.sharding.NamedSharding:
    """Sharding of arrays with a leading seed axis over :func:`num_devices` devices.

    Seeds never interact, so ``jit`` partitions the vmapped chunk along this axis with no
    communication: each device trains ``seeds / devices`` seeds. Multi-host: call
    ``jax.distributed.initialize()`` first; ``jax.devices()`` then lists every host's devices.
    """
    mesh = jax.sharding.Mesh(np.array(jax.devices()[:num_devices(cfg)]), ("seeds",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("seeds"))


def run_keys(cfg: TrainConfig, key: jax.Array) -> jax.Array:
    """One key per run ``[runs, 2]``: ``key`` split over the seeds, the same for every sweep
    point, so that seed ``s`` of each point meets the same randomness as in a plain run."""
    return jnp.tile(jax.random.split(key, cfg.seeds), (len(sweep_points(cfg)), 1))


def init_carry(cfg: TrainConfig, init: Callable, key: jax.Array):
    """Every run's initial training state (``init`` from :func:`build`), split along the
    run axis over the devices."""
    return init(jax.device_put(run_keys(cfg, key), shard_seeds(cfg)))


class TrainingFault(RuntimeError):
    """A seed's losses or parameters went non-finite; the run stopped before saving it."""


@jax.jit
def params_finite(carry) -> jax.Array:
    """Per seed ``[S]``: are all parameters of every agent in the carry finite?"""
    agents = [v for v in vars(carry).values() if isinstance(v, gc_td3.AgentState)]
    leaves = [x for a in agents for x in jax.tree.leaves(
        (a.actor_params, a.critic_params, a.critic_g_params))]
    return jnp.stack([jnp.isfinite(x).reshape(x.shape[0], -1).all(1) for x in leaves]).all(0)


def _check_finite(train_m: dict, finite_params: np.ndarray, step: int, chunk: int,
                  cfg: TrainConfig) -> None:
    """Stop on the first seed with a non-finite loss or parameter. Called before the chunk's
    rows and checkpoint are written, so both stay at the last good chunk."""
    losses = {k: v for k, v in train_m.items() if k.endswith("loss") or k in ("q", "high_q")}
    for r in range(cfg.runs):
        bad = [k for k, v in losses.items() if not np.isfinite(v[r])]
        if not finite_params[r]:
            bad.append("parameters")
        if bad:
            point = point_name(sweep_points(cfg)[r // cfg.seeds])
            s = f"{r % cfg.seeds}" + (f", {point}" if point else "")
            where = (f"; the last good checkpoint (chunk {chunk}) is in {_ckpt_dir(cfg.out)}"
                     if cfg.out and cfg.checkpoint_every and chunk else "")
            raise TrainingFault(f"seed {s}: non-finite {', '.join(bad)} in the chunk ending "
                                f"at env step {step}{where}")


def _ckpt_dir(out: str) -> str:
    return os.path.abspath(os.path.join(out, "checkpoints"))


def _checkpoints(root: str) -> list[str]:
    """The finished checkpoints in ``root``, oldest first. A write that was killed leaves an
    orbax temporary directory (``chunk_000003.orbax-checkpoint-tmp-...``): not one of them."""
    if not os.path.isdir(root):
        return []
    return sorted(d for d in os.listdir(root) if re.fullmatch(r"chunk_\d{6}", d))


def has_checkpoint(out: str) -> bool:
    """Whether the run directory ``out`` holds a finished checkpoint to ``--resume`` from."""
    return bool(_checkpoints(_ckpt_dir(out)))


def _nonempty_leaves(carry) -> dict:
    """The carry's leaves by index, without the zero-size ones (orbax refuses them; MJX's
    ``Data`` has some, e.g. ``act`` of a model without actuator state). Restoring takes those
    from the template, where they are just as empty."""
    return {str(i): x for i, x in enumerate(jax.tree.leaves(carry)) if x.size}


def _save(out: str, n_done: int, carry) -> None:
    """Checkpoint the carry after ``n_done`` chunks; orbax writes to a temporary directory and
    renames it, so a crash mid-write leaves the previous checkpoint whole. Keeps the last two."""
    import orbax.checkpoint as ocp

    root = _ckpt_dir(out)
    with ocp.StandardCheckpointer() as ckptr:
        ckptr.save(os.path.join(root, f"chunk_{n_done:06d}"), _nonempty_leaves(carry))
        ckptr.wait_until_finished()
    for old in _checkpoints(root)[:-2]:
        shutil.rmtree(os.path.join(root, old))


def _restore(cfg: TrainConfig, template) -> tuple[int, object, list[dict]]:
    """(chunks done, carry, metric rows up to that checkpoint) of the run in ``cfg.out``."""
    import orbax.checkpoint as ocp

    root = _ckpt_dir(cfg.out or "")
    done = _checkpoints(root)
    if not done:
        raise ConfigError(f"--resume: no checkpoint in {root}")
    n_done = int(done[-1].split("_")[1])
    target = jax.tree.map(ocp.utils.to_shape_dtype_struct, _nonempty_leaves(template))
    with ocp.StandardCheckpointer() as ckptr:
        saved = ckptr.restore(os.path.join(root, done[-1]), target)
    leaves, treedef = jax.tree.flatten(template)
    carry = jax.tree.unflatten(treedef, [saved.get(str(i), x) for i, x in enumerate(leaves)])
    path = os.path.join(cfg.out, "metrics.csv")
    point = sweep_points(cfg)[0]
    ints = {"step", "seed", "falls", *(k for k, v in point.items() if isinstance(v, int))}
    strs = {k for k, v in point.items() if isinstance(v, str)}
    with open(path) as f:
        rows = [{k: (v if k in strs else int(v) if k in ints else float(v))
                 for k, v in r.items()} for r in csv.DictReader(f)]
    rows = [r for r in rows if r["step"] <= n_done * cfg.steps_per_chunk]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, csv_fields(cfg))
        w.writeheader()
        w.writerows(rows)
    return n_done, carry, rows


def _progress(n_chunks: int, cfg: TrainConfig, done: int = 0):
    from tqdm import tqdm

    return tqdm(total=n_chunks, initial=done, unit="chunk",
                desc=f"{cfg.algo} {cfg.env} x{cfg.runs} runs", file=sys.stderr,
                dynamic_ncols=True)


def package_versions() -> dict[str, str]:
    """Versions of Python and of the packages a run's numbers depend on."""
    from importlib import metadata

    out = {"python": sys.version.split()[0]}
    for name in ("flrjax", "jax", "jaxlib", "mujoco", "mujoco-mjx", "brax", "flax", "optax",
                 "numpy", "orbax-checkpoint"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


#: Fields newer than saved runs, left out of :func:`config_dict` while None (their default),
#: so a run that does not set them saves, and compares with old config.json files (resume,
#: run_grid's grid.json and --adopt), as before they existed.
_OMITTED_WHEN_NONE = ("flr_value_chunk", "flr_precision")


def config_dict(cfg: TrainConfig) -> dict:
    """``cfg`` as config.json holds it (a sweep's tuples as lists), to compare with one."""
    d = json.loads(json.dumps(dataclasses.asdict(cfg)))
    return {k: v for k, v in d.items() if not (k in _OMITTED_WHEN_NONE and v is None)}


#: Files a run writes into its directory (besides config.json): a directory holding any of
#: them without a config.json is someone else's, and is never written into.
RUN_FILES = ("metrics.csv", "checkpoints", "summary.json", "curves.png")


def check_out(cfg: TrainConfig, *, new_run: bool = True) -> None:
    """Refuse, with a :class:`ConfigError`, an ``--out`` that cannot take the run: a file, a
    path under a file, a directory this process cannot write, a run's files without their
    config.json, or (``new_run``) another run's config.json. The command line checks all but
    the last before anything starts (a script may continue a run by its ``--out``);
    :func:`prepare_out` checks all of them before a new run writes anything."""
    out = cfg.out
    if not out:
        return
    if os.path.exists(out) and not os.path.isdir(out):
        raise ConfigError(f"--out {out} is a file, not a directory")
    parent = os.path.abspath(out)
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if not os.path.isdir(parent):
        raise ConfigError(f"--out {out}: {parent} is a file, not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"--out {out}: {parent} is not writable")
    path = os.path.join(out, "config.json")
    if os.path.exists(path) and new_run:
        try:
            with open(path) as f:
                old = json.load(f).get("config", {})
        except (OSError, ValueError, AttributeError):
            old = {}
        diff = sorted(k for k, v in config_dict(cfg).items() if old.get(k) != v)
        raise ConfigError(f"--out {out} already holds a run"
                          + (f" with a different config ({', '.join(diff)})" if diff else "")
                          + "; choose another --out (or --resume it)")
    found = [f for f in RUN_FILES if os.path.exists(os.path.join(out, f))]
    if found and not os.path.exists(path):
        raise ConfigError(f"--out {out} holds {', '.join(found)} but no config.json; choose "
                          "another --out")


def prepare_out(cfg: TrainConfig) -> None:
    """Create ``cfg.out`` with config.json (config, versions, device, git commit, command) and
    the CSV header; refuse a directory :func:`check_out` refuses."""
    check_out(cfg)
    try:
        os.makedirs(cfg.out, exist_ok=True)
        metrics_io.write_json(os.path.join(cfg.out, "config.json"), {
            "config": config_dict(cfg), "versions": package_versions(),
            "device": str(jax.devices()[0].device_kind), "git": metrics_io.git_state(),
            "command": shlex.join(sys.argv)})
        with open(os.path.join(cfg.out, "metrics.csv"), "w", newline="") as f:
            csv.writer(f).writerow(csv_fields(cfg))
    except OSError as e:
        raise ConfigError(f"--out {cfg.out}: {e.strerror or e}") from None


def _append_rows(out: str, rows: list[dict], fields: tuple[str, ...]) -> None:
    with open(os.path.join(out, "metrics.csv"), "a", newline="") as f:
        w = csv.DictWriter(f, fields)
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())


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
            parse = {"flr_next": str, "initial_episodes": int}.get(field, float)
            try:
                point.append((field, parse(value.strip())))
            except ValueError:
                kind = "an integer" if parse is int else "a number"
                raise argparse.ArgumentTypeError(f"{item!r}: not {kind}") from None
        if point:
            points.append(tuple(point))
    return tuple(points)


def _ints(text: str) -> int | tuple[int, ...]:
    """A flag's integer, or a tuple of them from a comma-separated list (a sweep)."""
    values = tuple(int(x) for x in text.split(","))
    return values if "," in text else values[0]


#: The sized and tuned flags: type and help. Each is checked by :func:`validate`.
FLAG_HELP: dict[str, tuple[type, str]] = {
    "steps": (int, "env steps per seed (all its envs); a multiple of envs x episode length x "
                   "episodes per chunk"),
    "num_envs": (int, "lockstep envs per seed"),
    "updates_per_step": (float, "gradient updates per env step (paper protocol: 1 with 1 env)"),
    "episodes_per_chunk": (int, "episode rounds per jitted chunk (one evaluation each)"),
    "eval_episodes": (int, "deterministic test episodes per evaluation (paper: 10)"),
    "batch_size": (int, "TD3 batch (reference: 1024)"),
    "hidden": (int, "width of the 3 hidden layers (reference: 256)"),
    "buffer_episodes": (int, "replay capacity in episodes, per seed"),
    "initial_episodes": (_ints, "random-action episodes before learning (DHRL: 200); "
                                "comma-separated values sweep it in one vmapped run"),
    "polyak": (float, "target networks: t <- polyak t + (1 - polyak) online"),
    "target_update_freq": (int, "updates between target-network steps (reference: 10)"),
    "episode_length": (int, "override the env's episode length"),
    "goal_radius": (float, "ant only: training goals within this of the start"),
    "subgoal_freq": (int, "dhrl: env steps per subgoal (ant: 40)"),
    "graph_start_steps": (int, "graph algos: env steps per seed before the first graph"),
    "graph_every_steps": (int, "graph algos: env steps per seed between rebuilds (ant: 9000)"),
    "cutoff": (float, "graph algos: longest graph edge, in estimated steps (ant: 30)"),
    "landmark_eps": (float, "graph algos: FPS stops once every state is this close (ant: 10)"),
    "max_landmarks": (int, "graph algos: most graph nodes (ant: 300)"),
    "landmark_sample": (int, "graph algos: replay states FPS picks from (ant: 6000)"),
    "checkpoint_every": (int, "chunks between checkpoints; 0 keeps none (default 1)"),
    "flr_alpha": (_floats, "flr_*: alpha of eq. 5 (paper 0.01; > 1 - gamma warns); "
                           "comma-separated values sweep it in one vmapped run"),
    "flr_eps": (_floats, "flr_*: next subgoals at distance >= eps (paper 2; <= 2 delta "
                         "warns); comma-separated values sweep it"),
    "flr_next": (_strs, "flr_*: 'sample' next subgoals on the eps ring, or the final 'goal'; "
                        "'sample,goal' sweeps it"),
    "flr_candidates": (int, "flr_*: next subgoals sampled per transition (default 16)"),
    "flr_value_chunk": (int, "flr_*: reaching transitions per V evaluation chunk (default: "
                             "the whole batch on a GPU, 128 on a CPU; 0: the whole batch)"),
    "flr_precision": (str, "flr_*: matrix operands of eq. 5's candidate values, float32 or "
                           "bfloat16 (float32 accumulation; default: bfloat16 on a GPU, "
                           "float32 on a CPU)"),
    "pig_jump_temp": (_floats, "pig, flr_pig: subgoal skipping, each hop with probability "
                               "jump_temp / imitation loss (default 10/30**2, the reference's "
                               "10 on torques of +-30; 0: off); comma-separated values sweep it"),
    "sweep": (_sweep, "sweep points, each FIELD=VALUE[, ...], split by ';' (e.g. 'flr-alpha=0; "
                      "flr-eps=0.5'); a field a point omits keeps its flag's value"),
    "devices": (int, "devices the seeds are sharded over (default: all that divide --seeds)"),
}


#: ``--help``'s groups of :data:`FLAG_HELP`'s flags (run flags and checkpoints add their own).
FLAG_GROUPS: dict[str, tuple[str, ...]] = {
    "run": ("steps", "devices"),
    "learner (sizes: the preset's unless given)": (
        "num_envs", "updates_per_step", "episodes_per_chunk", "eval_episodes", "batch_size",
        "hidden", "buffer_episodes", "initial_episodes", "polyak", "target_update_freq",
        "episode_length", "goal_radius"),
    "graph and DHRL (dhrl, flr_dhrl, pig, flr_pig, higl; default: the env's)": (
        "subgoal_freq", "graph_start_steps", "graph_every_steps", "cutoff", "landmark_eps",
        "max_landmarks", "landmark_sample"),
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


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: the usage block would bury the message."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def default_preset() -> str:
    """``--preset auto``: ``fast`` (the GPU figures' protocol) on a GPU, ``quick`` on a CPU."""
    return "quick" if jax.default_backend() == "cpu" else "fast"


def _preset_values(name: str) -> str:
    """``[quick 24000, paper 1200000, fast 1920000]`` for a flag the presets set, else its
    default where the help does not say it."""
    vals = [f"{p} {v[name]}" for p, v in PRESETS.items() if name in v]
    if vals:
        return f" [{', '.join(vals)}]"
    default = TrainConfig.__dataclass_fields__[name].default
    return "" if default is None or "default" in FLAG_HELP[name][1] else f" (default {default})"


def _parser() -> _Parser:
    p = _Parser(prog="python -m flrjax.train",
                description="Train a method of the paper on a maze: seeds and sweep points "
                            "vmapped in one jitted program.")
    run = p.add_argument_group("run")
    run.add_argument("--env", default=None,
                     help=f"one of {', '.join(envs.names())} (default {TrainConfig.env})")
    run.add_argument("--algo", default=None,
                     help=f"one of {', '.join(ALGOS)} (default {TrainConfig.algo})")
    run.add_argument("--preset", choices=["auto", *PRESETS], default="auto",
                     help="the sizes below: auto (default) is fast on a GPU, quick on a CPU")
    run.add_argument("--seeds", type=int, default=None, help="seeds trained at once, vmapped "
                     "(default 1)")
    run.add_argument("--seed", type=int, default=None, help="base random seed (default 0)")
    run.add_argument("--out", default=None,
                     help="run directory (default runs/<env>-<algo>-<date>-<time>)")
    run.add_argument("--tensorboard", action="store_true",
                     help="also write TensorBoard event files into the run directory")
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
                    help="do not keep compiled programs between runs (default: kept in "
                         f"{default_compile_cache()}, so a second launch skips compiling)")
    return p


def parse_cli(argv: list[str] | None = None) -> CLI:
    """CLI flags -> :class:`CLI`; one-line errors on bad input, before anything is written."""
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
        check_out(cfg, new_run=False)
    except ConfigError as e:
        p.error(str(e))
    return CLI(cfg, False, time_limit, cache, preset, tensorboard)


def _tuples(v):
    """JSON lists back to the config's (nested) tuples."""
    return tuple(_tuples(x) for x in v) if isinstance(v, list) else v


def _resume_config(p: argparse.ArgumentParser, args: argparse.Namespace) -> TrainConfig:
    """The config saved in ``--resume DIR``; flags given with it must agree with it."""
    path = os.path.join(args.resume, "config.json")
    if not os.path.isfile(path):
        p.error(f"--resume: {path} does not exist")
    try:
        with open(path) as f:
            saved = json.load(f)["config"]
        saved = TrainConfig(**{**{k: _tuples(v) for k, v in saved.items()}, "out": args.resume})
    except (OSError, ValueError, KeyError, TypeError) as e:
        p.error(f"--resume: {path} is not a flrjax run's config ({type(e).__name__}: {e})")
    given = {k: v for k, v in vars(args).items()
             if k not in ("resume", "preset", "out") and v is not None}
    differ = sorted(k for k, v in given.items() if v != getattr(saved, k))
    if differ:
        p.error(f"--resume: the run in {args.resume} was started with different "
                f"{', '.join(differ)}; drop those flags")
    return saved


def start_line(cli: CLI) -> str:
    """What a run is about to do, printed before it compiles."""
    cfg = cli.cfg
    chunks = cfg.steps // cfg.steps_per_chunk
    what = "resuming" if cli.resume else f"preset {cli.preset}"
    runs = f"{cfg.seeds} seed(s)" + (f" x {cfg.runs // cfg.seeds} sweep points"
                                     if cfg.runs > cfg.seeds else "")
    return (f"{metrics_io.METHOD_NAMES[cfg.algo]} ({cfg.algo}) on {cfg.env}, {runs}, {what}: "
            f"{cfg.steps:,} env steps per seed in {chunks} chunks of {cfg.steps_per_chunk:,}, "
            f"{cfg.num_envs} env(s) per seed, {cfg.updates_per_step:g} updates per env step; "
            f"{jax.devices()[0].device_kind} ({jax.default_backend()}). The first chunk "
            "compiles; the progress bar's estimate of the time left follows it.")


def finish(cfg: TrainConfig, rows: list[dict]) -> dict:
    """Write ``curves.png`` and ``summary.json`` into the run directory; the summary."""
    points = sweep_points(cfg)
    metrics_io.plot_curves(cfg.algo, points, cfg.seeds, rows, os.path.join(cfg.out, "curves.png"))
    path = os.path.join(cfg.out, "summary.json")
    metrics_io.write_json(path, {})  # listed among the files it names
    summary = metrics_io.summarize(cfg.algo, points, cfg.seeds, cfg.steps, rows, cfg.out)
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
        print(f"python -m flrjax.train: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except TrainingFault as e:
        print(f"python -m flrjax.train: stopped: {e}", file=sys.stderr)
        raise SystemExit(3) from None
    finally:
        if board is not None:
            board.close()
    if not rows:
        print(f"nothing to do: the run in {cfg.out} has all its {cfg.steps:,} steps")
        return
    head = ("done" if rows[-1]["step"] == cfg.steps else
            f"time limit: stopped with a checkpoint (continue: --resume {cfg.out})")
    print(f"{head}: {metrics_io.format_summary(finish(cfg, rows))}")


if __name__ == "__main__":
    main()
