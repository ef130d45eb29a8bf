"""Shared fixtures of the gc_td3 tests: one small config, bandit batches, a NumPy forward pass.

One config for every test, and the jitted functions defined once here, so each compiles once
per session whichever test files run.
"""

from __future__ import annotations

import jax
import numpy as np

from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import learner, losses

OBS, G, A, B = 4, 2, 2, 64  # obs (its first G entries are the achieved goal), goal, action, batch
CFG = gc_td3.TD3Config(hidden_sizes=(64, 64))
HP = gc_td3.Hparams.create(lr_actor=1e-3, gamma=0.5)

critic_step = jax.jit(learner.critic_step)
update_actor = jax.jit(learner.update_actor)
act = jax.jit(gc_td3.act)
critic_target = jax.jit(losses.critic_target)
critic_g_target = jax.jit(losses.critic_g_target)


def train_step(s, batch, batch_g, key, i):
    """The paper protocol's iteration ``i``: critics (+ distance critics), actor after odd ones."""
    s, m = critic_step(s, batch, key, batch_g)
    if i % CFG.actor_update_freq == CFG.actor_update_freq - 1:
        s, _ = update_actor(s, batch)
    return s, m


def new_state(seed: int = 0) -> gc_td3.AgentState:
    return gc_td3.init(jax.random.key(seed), OBS, G, A, CFG, HP)


def bandit_batch(rng: np.random.Generator, n: int = B) -> dict[str, np.ndarray]:
    """One-step contextual bandit: the best action is ``goal - obs[:2]``, reward -0.5 * error.

    ``next_obs = obs``, so with any gamma the optimal Q is the reward itself (V* = 0).
    """
    obs = rng.uniform(-0.5, 0.5, (n, OBS)).astype(np.float32)
    goal = rng.uniform(-0.5, 0.5, (n, G)).astype(np.float32)
    action = rng.uniform(-1.0, 1.0, (n, A)).astype(np.float32)
    reward = -0.5 * np.linalg.norm(action - (goal - obs[:, :G]), axis=-1)
    return dict(obs=obs, next_obs=obs, goal=goal, action=action, reward=reward.astype(np.float32))


def leaves_equal(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b),
                                                    strict=True))


# NumPy forward pass of the networks, independent of flax ------------------------------------


def np_mlp(params, x: np.ndarray) -> np.ndarray:
    layers = params["params"]["MLP_0"]
    names = sorted(layers, key=lambda s: int(s.rsplit("_", 1)[1]))
    for i, name in enumerate(names):
        x = x @ np.asarray(layers[name]["kernel"], np.float64) + np.asarray(layers[name]["bias"])
        if i < len(names) - 1:
            x = np.maximum(x, 0.0)
    return x


def np_policy(params, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
    x = np.concatenate([obs, goal - obs[:, :G]], axis=-1)  # relative goal (agent.py)
    return np.tanh(np_mlp(params, x)) * CFG.action_max


def np_q(twin, i: int, obs, goal, action) -> np.ndarray:
    params = jax.tree.map(lambda p: np.asarray(p)[i], twin)
    d = np_mlp(params, np.concatenate([obs, goal, action / CFG.action_max], axis=-1))[:, 0]
    return -(1.0 - HP.gamma**d) / (1.0 - HP.gamma)  # DistCritic
