"""What every method's ``evaluate`` shares: the episodes it starts and the metrics it reports.

Each method rolls out its own deterministic policy (with or without a planner) from
:func:`start_states` and reports :func:`final_metrics` of the last states. With ``trace=True``
(static) its ``evaluate`` also records every step (:func:`trace_step`) and returns
``(metrics, trace)`` (:func:`traced`), for drawing the episodes (:mod:`flrjax.episodes`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State

from flrjax.algos.common import batched
from flrjax.metric_names import scoped


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
    the other ``n`` did (can the learner reach goals like those it trained on); in ``eval/``
    (:mod:`flrjax.metric_names`)."""
    maze = jax.tree.map(lambda x: x[:n], info)
    return scoped("eval", {
        "success_rate": maze["success"].mean(),
        "final_goal_distance": maze["goal_distance"].mean(),
        "falls": maze["fallen"].sum(),
        "final_torso_z": maze["torso_z"].mean(),
        "random_goal_success": info["success"][n:].mean(),
        "random_goal_distance": info["goal_distance"][n:].mean(),
    })


def trace_step(s: State, waypoint: jax.Array, subgoal: jax.Array) -> dict:
    """One step of every evaluation episode, as :func:`traced` keeps it: the torso's xy and
    whether it is fallen before the step, the goal the low level chases in it (a planner's
    waypoint, else the subgoal) and the high level's subgoal (the final goal without one);
    for a MuJoCo body also its ``qpos``, to render the episode."""
    rec = {"xy": s.info["achieved_goal"], "fallen": s.info["fallen"], "waypoint": waypoint,
           "subgoal": subgoal}
    if s.pipeline_state is not None:
        rec["qpos"] = s.pipeline_state.qpos
    return rec


def traced(metrics: dict, steps: dict, final: State, n: int) -> tuple[dict, dict]:
    """``(metrics, trace)``: the :func:`trace_step` records ``steps`` of the first ``n``
    episodes (those to the maze's goal) as ``[n, T, ...]`` (the scans' time axes lead and are
    flattened in order), with their final xy, fallen and success."""
    lead = steps["fallen"].ndim - 1  # the time axes before the episode axis

    def per_episode(x):
        x = x.reshape(-1, *x.shape[lead:])
        return jnp.swapaxes(x, 0, 1)[:n]

    trace = jax.tree.map(per_episode, steps)
    trace.update(final_xy=final.info["achieved_goal"][:n], final_fallen=final.info["fallen"][:n],
                 success=final.info["success"][:n])
    return metrics, trace
