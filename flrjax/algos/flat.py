"""``--algo flat``: the hierarchy's goal-conditioned low level with no high level, trained
straight at the episode's final goal.

One seed's whole training state is a :class:`Carry`; :func:`train_episode` runs one episode of
``T`` env steps in ``num_envs`` lockstep envs by :mod:`flrjax.algos.hierarchy`'s low level
(acting, storing into the HER buffer, the round's updates) with the sparse reward and no
distance critics' batches (no planner reads them), and :func:`evaluate` is the hierarchy's
evaluation with no high level. Both are pure functions: the trainer ``vmap``s them over seeds
and ``scan``s episodes.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State
from flax import struct

from flrjax import replay
from flrjax.agents import gc_td3
from flrjax.algos import hierarchy, rollout
from flrjax.algos.common import (
    BaseConfig,
    HEROptions,
    Run,
    base_fields,
    reset_envs,
    td3_config,
    td3_hparams,
)
from flrjax.algos.registry import Method, register
from flrjax.metric_names import scoped
from flrjax.rewards import sparse_reward


@dataclasses.dataclass(frozen=True)
class FlatConfig(BaseConfig):
    """What the flat learner needs from the run: the shared fields, its TD3 (static) and the
    point's values of its traced numbers (the agent's state carries them), named as the
    hierarchy's low level."""

    low: gc_td3.TD3Config
    low_hp: gc_td3.Hparams


@dataclasses.dataclass(frozen=True)
class FlatOptions(HEROptions):
    """The flat learner's flags: its HER."""


def from_run(run: Run, env: Env) -> FlatConfig:
    """The run's flags as the flat learner's config."""
    return FlatConfig(**base_fields(run, env), low=td3_config(run), low_hp=td3_hparams(run))


def hparams(cfg: FlatConfig) -> gc_td3.Hparams:
    """The traced numbers :func:`init` puts in the agent's state."""
    return cfg.low_hp


def resolved(cfg: FlatConfig) -> dict:
    """The updates' matrix operands (their default follows the device)."""
    return {"train_precision": cfg.low.train_precision}


@struct.dataclass
class Carry:
    env_state: State  # [num_envs]
    buffer: replay.ReplayState
    agent: gc_td3.AgentState
    key: jax.Array


def init(key: jax.Array, env: Env, cfg: FlatConfig, hp: gc_td3.Hparams | None = None
         ) -> Carry:
    """A fresh seed: agent (with ``hp``, default :func:`hparams`), empty buffer (the
    hierarchy's low level's), ``num_envs`` envs reset."""
    k_agent, k_env, k_carry = jax.random.split(key, 3)
    agent = gc_td3.init(k_agent, env.observation_size, 2, env.action_size, cfg.low,
                        hparams(cfg) if hp is None else hp)
    buffer = replay.init(cfg.buffer_episodes, env.config.episode_length, cfg.num_envs,
                         *hierarchy.low_spec(env))
    env_state = reset_envs(env, k_env, cfg.num_envs)
    return Carry(env_state=env_state, buffer=buffer, agent=agent, key=k_carry)


def _sampler(buffer: replay.ReplayState, cfg: FlatConfig):
    """HER batches of the buffer with the sparse reward (eq. 1) of their relabelled goals."""

    def sample(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = replay.sample(buffer, key, cfg.low.batch_size, future_p=agent.hp.future_p,
                              future_step=cfg.low.future_step)
        batch["reward"] = sparse_reward(batch["next_achieved_goal"], batch["goal"],
                                        delta=cfg.delta)
        return batch

    return sample


def learn(agent: gc_td3.AgentState, buffer: replay.ReplayState, key: jax.Array,
          learning: jax.Array, critic_updates: int, actor_updates: int, cfg: FlatConfig
          ) -> tuple[gc_td3.AgentState, dict]:
    """:func:`gc_td3.learn_if` on HER batches of ``buffer`` with the sparse reward."""
    names = ("critic_loss", "q", "reward") if critic_updates else ("actor_loss",)
    agent, m = gc_td3.learn_if(learning, agent, _sampler(buffer, cfg), key, names,
                               critic_updates=critic_updates, actor_updates=actor_updates)
    return agent, scoped("low", m)


def learn_alone(carry: Carry, key: jax.Array, iters: int, cfg: FlatConfig
                ) -> gc_td3.AgentState:
    """The updates of ``iters`` env steps of :func:`train_episode`, without its acting: each
    step's critic updates and each group's actor updates, on HER batches of the carry's
    buffer (:attr:`Method.learn_alone`)."""
    group, actor_updates = gc_td3.schedule(cfg.updates_per_iter, cfg.low.actor_update_freq)
    yes = jnp.bool_(True)

    def one_group(agent, k):
        k_c, k_a = jax.random.split(k)
        agent, _ = jax.lax.scan(
            lambda a, kk: learn(a, carry.buffer, kk, yes, cfg.updates_per_iter, 0, cfg),
            agent, jax.random.split(k_c, group))
        return learn(agent, carry.buffer, k_a, yes, 0, actor_updates, cfg)[0], None

    return jax.lax.scan(one_group, carry.agent, jax.random.split(key, iters // group))[0]


def train_episode(carry: Carry, episode: jax.Array, env: Env, cfg: FlatConfig
                  ) -> tuple[Carry, dict]:
    """One round of lockstep episodes of the hierarchy's low level with no high level: it
    acts towards the final goal (:func:`hierarchy.act_and_store`, random in the initial
    rounds, :func:`hierarchy.start_round`), each env step makes ``updates_per_iter`` critic
    updates and each group of steps the actor's (:func:`hierarchy.actor_catch_up`), all
    scanned by :func:`rollout.train`. ``episode`` is the unbatched round index."""
    rnd = hierarchy.start_round(episode, cfg)
    key, k_reset = jax.random.split(carry.key)
    env_state = reset_envs(env, k_reset, cfg.num_envs)

    def step(c, t):
        env_state, buffer, agent, key = c
        key, k_act, k_rand, k_upd = jax.random.split(key, 4)
        nxt, buffer, _ = hierarchy.act_and_store(agent, env, env_state, env_state.info["goal"],
                                                 t, buffer, (k_act, k_rand), rnd.random_phase)
        agent, m = learn(agent, buffer, k_upd, rnd.learning, cfg.updates_per_iter, 0, cfg)
        return (nxt, buffer, agent, key), (m, None)

    (env_state, buffer, agent, key), metrics = rollout.train(
        step, hierarchy.actor_catch_up(rnd, lambda buffer: _sampler(buffer, cfg)),
        (env_state, carry.buffer, carry.agent, key), env.config.episode_length, rnd.group)
    metrics = hierarchy.round_metrics(metrics, env_state)
    return Carry(env_state=env_state, buffer=replay.finish_episodes(buffer), agent=agent,
                 key=key), metrics


def evaluate(carry: Carry, key: jax.Array, env: Env, cfg: FlatConfig, trace: bool = False):
    """The hierarchy's evaluation with no high level (:func:`hierarchy.evaluate`): the
    deterministic policy from the start towards ``env.maze.goal`` (the paper's evaluation) and
    towards as many goals drawn as in training (``random_goal_*``). ``trace``: also every
    step's record (:func:`rollout.traced`)."""
    s, _, rec = hierarchy.evaluate(carry.agent, key, env, cfg.eval_episodes, trace)
    return rollout.report(s, cfg.eval_episodes, rec, trace)


def params(carry: Carry) -> tuple:
    """The agent's trained parameters."""
    return gc_td3.trained(carry.agent)


register(Method("flat", "flat TD3+HER", FlatOptions, from_run, hparams, init, train_episode,
                evaluate, params, resolved=resolved, learn_alone=learn_alone))
