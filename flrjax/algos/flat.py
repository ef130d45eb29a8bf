"""``--algo flat``: the goal-conditioned low level trained straight at the episode's final goal.

One seed's whole training state is a :class:`Carry`; :func:`train_episode` runs one episode of
``T`` env steps in ``num_envs`` lockstep envs, storing into the HER buffer and doing
``updates_per_iter`` TD3 updates per step (once the initial random episodes are done), and
:func:`evaluate` runs the deterministic policy from the evaluation start to the evaluation goal.
Both are pure functions: the trainer ``vmap``s them over seeds and ``scan``s episodes.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State
from flax import struct

from flrjax import replay
from flrjax.agents import gc_td3
from flrjax.algos import evaluation
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


def _spec(env: Env) -> tuple[dict, dict]:
    obs = jax.ShapeDtypeStruct((env.observation_size,), jnp.float32)
    g = jax.ShapeDtypeStruct((2,), jnp.float32)
    act = jax.ShapeDtypeStruct((env.action_size,), jnp.float32)
    states = {"obs": obs, "achieved_goal": g, "torso_z": jax.ShapeDtypeStruct((), jnp.float32)}
    return states, {"action": act, "goal": g}


def init(key: jax.Array, env: Env, cfg: FlatConfig, hp: gc_td3.Hparams | None = None
         ) -> Carry:
    """A fresh seed: agent (with ``hp``, default :func:`hparams`), empty buffer, ``num_envs``
    envs reset."""
    k_agent, k_env, k_carry = jax.random.split(key, 3)
    agent = gc_td3.init(k_agent, env.observation_size, 2, env.action_size, cfg.low,
                        hparams(cfg) if hp is None else hp)
    states, transitions = _spec(env)
    buffer = replay.init(cfg.buffer_episodes, env.config.episode_length, cfg.num_envs,
                         states, transitions)
    env_state = reset_envs(env, k_env, cfg.num_envs)
    return Carry(env_state=env_state, buffer=buffer, agent=agent, key=k_carry)


def state_fields(s: State) -> dict:
    return {"obs": s.obs, "achieved_goal": s.info["achieved_goal"], "torso_z": s.info["torso_z"]}


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


def train_episode(carry: Carry, episode: jax.Array, env: Env, cfg: FlatConfig
                  ) -> tuple[Carry, dict]:
    """One lockstep episode in every env. ``episode`` (the same for all seeds, not vmapped) is
    the index of this episode round; rounds before ``initial_episodes / num_envs`` act at random
    and skip updates, as the reference's initial rollouts do.

    Updates follow :func:`gc_td3.schedule`: every env step makes ``updates_per_iter`` critic
    steps, and after each group of env steps the actor catches up (1 step per 2 critic steps).
    """
    horizon = env.config.episode_length
    group, actor_updates = gc_td3.schedule(cfg.updates_per_iter, cfg.low.actor_update_freq)
    random_phase = episode * cfg.num_envs < cfg.initial_episodes
    key, k_reset = jax.random.split(carry.key)
    env_state = reset_envs(env, k_reset, cfg.num_envs)

    def step(c, t):
        env_state, buffer, agent, key = c
        key, k_act, k_rand, k_upd = jax.random.split(key, 4)
        goal = env_state.info["goal"]
        action = jax.lax.cond(
            random_phase,
            lambda: jax.random.uniform(k_rand, (cfg.num_envs, env.action_size), minval=-1.0),
            lambda: gc_td3.act(agent, env_state.obs, goal, k_act, explore=True),
        )
        nxt = jax.vmap(env.step)(env_state, action)
        buffer = replay.insert_step(buffer, t, {**state_fields(env_state), "action": action,
                                                "goal": goal})
        # The final state's slot is rewritten every step; the last write (t = T-1) stays.
        buffer = replay.insert_final(buffer, state_fields(nxt))
        agent, m = learn(agent, buffer, k_upd, ~random_phase, cfg.updates_per_iter, 0, cfg)
        return (nxt, buffer, agent, key), m

    def group_of_steps(c, ts):
        c, m = jax.lax.scan(step, c, ts)
        env_state, buffer, agent, key = c
        key, k_upd = jax.random.split(key)
        agent, m_actor = learn(agent, buffer, k_upd, ~random_phase, 0, actor_updates, cfg)
        return (env_state, buffer, agent, key), {**jax.tree.map(jnp.mean, m), **m_actor}

    (env_state, buffer, agent, key), metrics = jax.lax.scan(
        group_of_steps, (env_state, carry.buffer, carry.agent, key),
        jnp.arange(horizon).reshape(-1, group))
    buffer = replay.finish_episodes(buffer)
    metrics = jax.tree.map(jnp.mean, metrics)
    metrics["stats/train_success"] = env_state.info["success"].mean()
    metrics["stats/physics_resets"] = env_state.info["physics_resets"].sum().astype(jnp.float32)
    return Carry(env_state=env_state, buffer=buffer, agent=agent, key=key), metrics


def evaluate(carry: Carry, key: jax.Array, env: Env, cfg: FlatConfig, trace: bool = False):
    """Deterministic-policy episodes: ``eval_episodes`` from the start towards ``env.maze.goal``
    (the paper's evaluation) and as many towards goals drawn as in training (``random_goal_*``:
    can the learner reach goals near where it has been). ``trace``: also every step's record
    (:func:`evaluation.traced`)."""
    n = cfg.eval_episodes
    s0 = evaluation.start_states(env, key, n)

    def step(s, _):
        goal = s.info["goal"]
        a = gc_td3.act(carry.agent, s.obs, goal, key, explore=False)
        return jax.vmap(env.step)(s, a), evaluation.trace_step(s, goal, goal) if trace else None

    s, rec = jax.lax.scan(step, s0, None, length=env.config.episode_length)
    metrics = evaluation.final_metrics(s.info, n)
    return evaluation.traced(metrics, rec, s, n) if trace else metrics


def params(carry: Carry) -> tuple:
    """The agent's trained parameters."""
    return gc_td3.trained(carry.agent)


register(Method("flat", "flat TD3+HER", FlatOptions, from_run, hparams, init, train_episode,
                evaluate, params, resolved=resolved))
