"""The low level's HER batches (replay.py ``LowReplay.sample`` / ``sample_g``) and their rewards:
the main critics' batch with eq. (1)'s sparse reward or FLR's eq. (5) (:mod:`flrjax.algos.flr`),
summed over ``n_step`` stored steps where asked; the distance critics' batch with eq. (1), so
that the planner's distances stay step counts; the actor's batch without a reward; and Fig. 4b's
reward statistics per episode (:func:`reward_gap`)."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from flrjax import replay, rewards
from flrjax.agents import gc_td3
from flrjax.algos import flr
from flrjax.metric_names import scoped

#: A :class:`flrjax.algos.hierarchy.HierarchyConfig` (its levels' TD3, ``flr`` and ``delta``),
#: as these functions read it: the hierarchy imports this module.
HierarchyConfig = Any

#: Training metrics of the low-level reward, summed over a batch (ratios are taken per
#: episode): reaching transitions from upright / fallen states and their rewards (Fig. 4b),
#: reaching transitions with no qualifying FLR candidate, and the transitions sampled.
REWARD_STATS = ("reach_up_n", "reach_up_reward", "reach_fall_n", "reach_fall_reward",
                "flr_no_candidate", "sampled_n")


def low_reward(agent: gc_td3.AgentState, batch: dict, key: jax.Array, cfg: HierarchyConfig
               ) -> tuple[jax.Array, dict]:
    """The low level's reward of a HER batch and its :data:`REWARD_STATS`: eq. (1), or with
    ``cfg.flr`` eq. (5) (:func:`flr.label`) with candidates in the high level's subgoal box."""
    if cfg.flr is None:
        reward = rewards.sparse_reward(batch["next_achieved_goal"], batch["goal"],
                                       delta=cfg.delta)
        reached = reward == 0.0
        no_candidate = jnp.zeros_like(reached)
    else:
        scale = jnp.asarray(cfg.high.action_max)
        offset = jnp.asarray(cfg.high.action_offset)
        out = flr.label(agent, batch, key, cfg.flr, delta=cfg.delta, low=offset - scale,
                        high=offset + scale)
        reward, reached = out.reward, out.reached
        no_candidate = reached & (out.num_qualified == 0)
    up, fall = reached & ~batch["next_fallen"], reached & batch["next_fallen"]
    stats = {"reach_up_n": up.sum(), "reach_up_reward": jnp.where(up, reward, 0.0).sum(),
             "reach_fall_n": fall.sum(), "reach_fall_reward": jnp.where(fall, reward, 0.0).sum(),
             "flr_no_candidate": no_candidate.sum(), "sampled_n": jnp.asarray(reached.size)}
    return reward, jax.tree.map(lambda x: x.astype(jnp.float32), stats)


def n_step_batch(buffer: replay.ReplayState, agent: gc_td3.AgentState, batch: dict,
                 key: jax.Array, cfg: HierarchyConfig) -> dict:
    """A main-critic batch with :func:`low_reward` already given, as ``cfg.low.n_step``
    stored steps: ``reward`` the sum over steps ``i`` of ``gamma**i`` times step ``i``'s
    reward under the batch's goal (eq. 1 or eq. 5), ``next_obs`` the state after the last,
    ``discount`` ``gamma**steps``; fewer steps where the episode ends sooner. The batch's
    reward statistics stay those of its own transitions (step 0)."""
    idx = replay.HerIndices(batch["slot"], batch["t"], batch["offset"], batch["relabelled"])
    gamma = agent.hp.gamma

    def step(carry, i):
        ret, discount, next_obs = carry
        ahead = replay.gather_ahead(buffer, idx, i)
        ahead.update(goal=batch["goal"], final_goal=batch["final_goal"])
        reward, _ = low_reward(agent, ahead, jax.random.fold_in(key, i), cfg)
        ok = ahead["valid"]
        return (ret + jnp.where(ok, discount * reward, 0.0),
                jnp.where(ok, discount * gamma, discount),
                jnp.where(ok[:, None], ahead["next_obs"], next_obs)), None

    start = (batch["reward"], jnp.full_like(batch["reward"], gamma), batch["next_obs"])
    (ret, discount, next_obs), _ = jax.lax.scan(step, start, jnp.arange(1, cfg.low.n_step))
    return {**batch, "reward": ret, "discount": discount, "next_obs": next_obs}


def low_samplers(buffer: replay.ReplayState, cfg: HierarchyConfig):
    """(sample, sample_g, sample_actor) of the low level: HER batches (future_p 0.8 and 1;
    replay.py ``LowReplay.sample`` / ``sample_g``). The main critics' batch gets
    :func:`low_reward` (sparse or FLR; over ``n_step`` steps, :func:`n_step_batch`); the
    distance critics' batch keeps the sparse reward, so that the planner's distances stay
    step counts. The actor's batch is the main one without a reward: the actor loss reads
    none, and the FLR's candidate values are the costliest part of a batch."""

    def sample_actor(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = replay.sample(buffer, jax.random.split(key)[0], cfg.low.batch_size,
                              future_p=agent.hp.future_p, future_step=cfg.low.future_step)
        if cfg.low.horizon is not None:  # any steps left fit a transition: the k-step value
            batch["steps_left"] = jax.random.randint(  # at every horizon is learned from it
                jax.random.fold_in(key, 1), (cfg.low.batch_size,), 1, cfg.low.horizon + 1)
        return batch

    def sample(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = sample_actor(agent, key)
        batch["reward"], batch["metrics"] = low_reward(agent, batch, jax.random.split(key)[1],
                                                       cfg)
        if cfg.low.n_step > 1:
            batch = n_step_batch(buffer, agent, batch, jax.random.fold_in(key, 2), cfg)
        if cfg.low.reach_ends:  # the subgoal's episode ends where eq. (1) / (5) pays reaching
            batch["reached"] = rewards.reached_mask(batch["next_achieved_goal"], batch["goal"],
                                                    delta=cfg.delta)
        return batch

    def sample_g(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = replay.sample(buffer, key, cfg.low.batch_size, future_p=agent.hp.future_p_g,
                              future_step=cfg.low.future_step)
        batch["reward"] = rewards.sparse_reward(batch["next_achieved_goal"], batch["goal"],
                                                delta=cfg.delta)
        return batch

    return sample, sample_g, sample_actor


def reward_gap(m: dict) -> dict:
    """Fig. 4b from the episode's :data:`REWARD_STATS` (consumed): mean reward of subgoal-
    reaching transitions from upright and from fallen states, their gap (NaN when a group is
    empty), the fraction of sampled transitions that reach their subgoal (those whose FLR
    reward is computed; NaN before learning starts), and the fraction of reaching transitions
    that are fallen and that had no FLR candidate."""
    up_n, fall_n, sampled_n = (m.pop(f"stats/{k}") for k in ("reach_up_n", "reach_fall_n",
                                                               "sampled_n"))
    up = m.pop("stats/reach_up_reward") / jnp.where(up_n > 0, up_n, jnp.nan)
    fall = m.pop("stats/reach_fall_reward") / jnp.where(fall_n > 0, fall_n, jnp.nan)
    reach_n = jnp.maximum(up_n + fall_n, 1e-9)
    return scoped("stats", {
        "reach_reward_upright": up, "reach_reward_fallen": fall, "reward_gap": up - fall,
        "reach_frac": (up_n + fall_n) / jnp.where(sampled_n > 0, sampled_n, jnp.nan),
        "reach_fallen_frac": fall_n / reach_n,
        "flr_no_candidate_frac": m.pop("stats/flr_no_candidate") / reach_n})
