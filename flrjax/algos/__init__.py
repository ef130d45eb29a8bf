"""Training algorithms, each a set of pure per-seed functions the trainer vmaps and scans, with
its config dataclass and its translation from the run's flags (``from_run``)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from flrjax.agents import gc_td3

if TYPE_CHECKING:
    from brax.envs.base import Env

    from flrjax.config import TrainConfig


@dataclasses.dataclass(frozen=True)
class BaseConfig:
    """What every method takes from the run (static); each method's config adds its own."""

    num_envs: int  # lockstep envs per seed
    updates_per_iter: int  # gradient updates per vectorised env step
    buffer_episodes: int  # replay capacity per seed
    initial_episodes: int  # per seed, over all envs: random actions, no updates (DHRL: 200)
    eval_episodes: int
    delta: float  # success radius of eq. (1) (0.5)


def base_fields(run: TrainConfig, env: Env) -> dict:
    """The run's flags as :class:`BaseConfig`'s fields."""
    return dict(num_envs=run.num_envs, updates_per_iter=run.updates_per_iter,
                buffer_episodes=run.buffer_episodes, initial_episodes=run.initial_episodes,
                eval_episodes=run.eval_episodes, delta=env.config.delta)


def td3_config(run: TrainConfig) -> gc_td3.TD3Config:
    """The goal-conditioned TD3 of the run's learner flags (network width, batch, targets,
    the updates' precision: float32 unless ``--train-precision`` says otherwise)."""
    return gc_td3.TD3Config(hidden_sizes=(run.hidden,) * 3, batch_size=run.batch_size,
                            polyak=run.polyak, target_update_freq=run.target_update_freq,
                            train_precision=run.train_precision or "float32")
