"""What every method's ``evaluate`` shares: the episodes it starts and the metrics it reports.

Each method rolls out its own deterministic policy (with or without a planner) from
:func:`start_states` and reports :func:`final_metrics` of the last states.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State

from flrjax.algos import batched


def start_states(env: Env, key: jax.Array, n: int) -> State:
    """``2n`` fresh episodes: the first ``n`` from the start towards ``env.maze.goal`` (the
    paper's evaluation), the other ``n`` towards goals drawn as in training; every field
    :func:`~flrjax.algos.batched`."""
    k_maze, k_rand = jax.random.split(key)
    goal = jnp.asarray(env.maze.goal)
    s_maze = jax.vmap(lambda k: env.reset_with_goal(k, goal))(jax.random.split(k_maze, n))
    s_rand = jax.vmap(env.reset)(jax.random.split(k_rand, n))
    return batched(jax.tree.map(lambda a, b: jnp.concatenate([a, b]), s_maze, s_rand))


def final_metrics(info: dict, n: int) -> dict:
    """The paper's metrics over the first ``n`` episodes' final states (success within 5 of
    the goal, distance, episodes ending fallen, torso height) and, as ``random_goal_*``, how
    the other ``n`` did (can the learner reach goals like those it trained on)."""
    maze = jax.tree.map(lambda x: x[:n], info)
    return {
        "success_rate": maze["success"].mean(),
        "final_goal_distance": maze["goal_distance"].mean(),
        "falls": maze["fallen"].sum(),
        "final_torso_z": maze["torso_z"].mean(),
        "random_goal_success": info["success"][n:].mean(),
        "random_goal_distance": info["goal_distance"][n:].mean(),
    }
