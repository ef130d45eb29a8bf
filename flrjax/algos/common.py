"""What the methods share: the fields every method's config takes from the run, the run's
device split, the low level's TD3 and traced numbers from the run's flags, and fresh env states.

``run`` is a :class:`flrjax.config.TrainConfig` (the shared flags, the method's own as
attributes too); this module and the methods read it and never import it: the config sits
above them."""

from __future__ import annotations

import dataclasses
import functools
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
from jax import custom_batching

from flrjax.agents import gc_td3
from flrjax.algos import registry
from flrjax.options import Sweepable, flag

if TYPE_CHECKING:
    from brax.envs.base import Env, State

#: A :class:`flrjax.config.TrainConfig`, as the methods read it.
Run = Any


@dataclasses.dataclass(frozen=True)
class BaseConfig:
    """What every method takes from the run (static); each method's config adds its own."""

    num_envs: int  # lockstep envs per seed
    updates_per_iter: int  # gradient updates per vectorised env step
    buffer_episodes: int  # replay capacity per seed
    initial_episodes: int  # per seed, over all envs: random actions, no updates (DHRL: 200)
    eval_episodes: int
    delta: float  # success radius of eq. (1) (0.5)


#: --help's sections of the learners' sizes and settings, and of their traced numbers
#: (TrainConfig's flags and the methods' own).
LEARNER = "learner (sizes: the preset's unless given)"
NUMBERS = ("learner numbers (each run's own: a comma list trains them as sweep points in one "
           "program)")


@dataclasses.dataclass(frozen=True)
class HEROptions:
    """The flags of a method whose low level learns from HER batches."""

    future_p: float | tuple[float, ...] | None = flag(
        None, "chance that the low level's HER relabels a batch's goal (default: the "
              "reference's 0.8); comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("HER future_p", gc_td3.Hparams.future_p, in_state=True),
        check=(lambda v: 0 <= v <= 1, "in [0, 1]"))


def base_fields(run: Run, env: Env) -> dict:
    """The run's flags as :class:`BaseConfig`'s fields."""
    return dict(num_envs=run.num_envs, updates_per_iter=run.updates_per_iter,
                buffer_episodes=run.buffer_episodes, initial_episodes=run.initial_episodes,
                eval_episodes=run.eval_episodes, delta=env.config.delta)


def num_devices(run: Run) -> int:
    """How many devices the run axis (seeds x sweep points) is split over: ``run.devices``,
    else every device JAX sees (every process's, under ``jax.distributed``); in one process
    never more than there are runs, so that no device trains padding alone. The runs are
    padded to a multiple of it (:func:`padded_runs`)."""
    n = jax.device_count() if run.devices is None else run.devices
    return n if jax.process_count() > 1 else min(n, run.runs)


def padded_runs(run: Run) -> int:
    """The run axis as the programs hold it: ``run.runs`` rounded up to a multiple of
    :func:`num_devices`. The padding runs, after the real ones, train with the last run's
    values and their own keys; no output shows them."""
    d = num_devices(run)
    return -(-run.runs // d) * d


def train_precision(run: Run) -> str:
    """Matrix operands of the run's updates: ``--train-precision``, else bfloat16 on a GPU for
    a method whose learning with them was checked (:attr:`registry.Method.train_bf16_gpu`)
    and float32 elsewhere."""
    if run.train_precision is not None:
        return run.train_precision
    gpu = jax.default_backend() == "gpu"
    return "bfloat16" if gpu and registry.get(run.algo).train_bf16_gpu else "float32"


def td3_config(run: Run, **fields) -> gc_td3.TD3Config:
    """The static goal-conditioned TD3 of the run's learner flags (network width, batch,
    target period, the updates' precision: :func:`train_precision`) and ``fields``."""
    return gc_td3.TD3Config(hidden_sizes=(run.hidden,) * 3, batch_size=run.batch_size,
                            target_update_freq=run.target_update_freq,
                            train_precision=train_precision(run),
                            critic_layer_norm=run.critic_layer_norm, obs_norm=run.obs_norm,
                            **fields)


def td3_hparams(run: Run) -> gc_td3.Hparams:
    """The low level's traced numbers from one sweep point's flags (Python numbers: the
    derived ``one_minus_gamma`` is exact before rounding); unset ``gamma`` and ``future_p``
    keep the reference's (a method without HER has no ``future_p``)."""
    unset = {k: v for k in ("gamma", "future_p") if (v := getattr(run, k, None)) is not None}
    return gc_td3.Hparams.create(lr_actor=run.lr_actor, lr_critic=run.lr_critic,
                                 polyak=run.polyak, noise_eps=run.noise_eps,
                                 random_eps=run.random_eps, target_noise=run.target_noise,
                                 **unset)


def batched(tree):
    """``tree`` itself; under a vmap every leaf comes out batched (a leaf that does not depend
    on the mapped inputs is broadcast along the vmapped axis). For fresh env states: fields
    that start as constants (MJX data's) are not batched over the trainer's runs, so the
    vmap of a ``lax.scan`` they start would batch its body, find those fields batched after a
    step, and batch the body (and every loop in it) again, down to the physics substeps:
    about a second of the ant's chunk trace, and as much of its evaluation's. The values are
    the same; a field that no step changes is carried once per run (a few KB in all). The
    batching rule sees the leaves as a flat list, so a pytree that converts its fields when
    rebuilt (brax's ``UInt64``) keeps its batched flags bools."""
    leaves, tree_def = jax.tree.flatten(tree)
    return jax.tree.unflatten(tree_def, _batched_leaves(leaves))


@custom_batching.custom_vmap
def _batched_leaves(leaves: list) -> list:
    return leaves


@_batched_leaves.def_vmap
def _batched_rule(axis_size, in_batched, leaves):
    return ([x if b else jnp.broadcast_to(x, (axis_size, *x.shape))
             for x, b in zip(leaves, in_batched[0], strict=True)],
            [True] * len(leaves))


@functools.partial(jax.jit, static_argnums=(0, 2))
def reset_envs(env: Env, key: jax.Array, n: int) -> State:
    """``n`` fresh episodes, every field :func:`batched`. Jitted: a method's ``init`` has
    traced it (and batched it over the runs) by the time its chunk resets the envs again,
    every round, and the chunk takes that trace."""
    return batched(jax.vmap(env.reset)(jax.random.split(key, n)))
