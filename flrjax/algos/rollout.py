"""The one rollout driver: every method's training episode and evaluation are scans of the
method's own step over the ``T`` env steps of ``E`` lockstep envs.

A method supplies callables in the paper's terms and this module scans them:

- training (:func:`train`): the low level's env step (act, store, update the critics), after
  each group of steps a hook (the actor's catch-up, :func:`gc_td3.schedule`), and where the
  method has a high level (:class:`High`), subgoal periods of ``k`` steps: at a period's start
  the high level chooses the subgoal, at its end it stores its transition and learns. Without
  a high level the groups run over the whole episode;
- evaluation (:func:`unroll`, :func:`unroll_periods`): a deterministic policy (a
  :class:`Decision` per step) from :func:`start_states`, re-planned by the high level at each
  period's start where it has one; :func:`report` gives :func:`final_metrics` of the last
  states and, with ``trace=True`` (static), every step's record (:func:`traced`), for drawing
  the episodes (:mod:`flrjax.episodes`).

brax's ``training/acting.py`` has the same split (``generate_unroll`` scans a policy's steps,
``Evaluator`` runs it from fresh states and reports the episodes' metrics).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State

from flrjax.algos.common import batched
from flrjax.metric_names import scoped

#: A training step at env time ``t``: ``(carry, t) -> (carry, (metrics, outputs))``.
Step = Callable[[Any, jax.Array], tuple[Any, tuple[dict, Any]]]
#: The hook after each group of steps: ``carry -> (carry, metrics)``.
AfterGroup = Callable[[Any], tuple[Any, dict]]


# --------------------------------------------------------------------------------------------
# Training episodes
# --------------------------------------------------------------------------------------------


class High(NamedTuple):
    """A high level's hooks around each subgoal period of ``period`` env steps.

    ``choose(carry, p)`` at the start of period ``p`` gives the period's low-level carry (what
    :func:`train`'s step scans) and a context the end of the period reads (e.g. the subgoal and
    a key for the high level's updates). ``finish(carry, low_carry, context, p, metrics,
    outputs)`` at its end (``metrics``: per group ``[k / group]``; ``outputs``: the steps'
    ``[k / group, group, ...]``) stores and learns, and gives the carry and the period's
    metrics."""

    period: int
    choose: Callable[[Any, jax.Array], tuple[Any, Any]]
    finish: Callable[[Any, Any, Any, jax.Array, dict, Any], tuple[Any, dict]]


def period_times(p: jax.Array | int, k: int, group: int) -> jax.Array:
    """The env times of period ``p`` (``k`` steps), in groups: ``[k / group, group]``."""
    return p * k + jnp.arange(k).reshape(-1, group)


def in_groups(step: Step, after_group: AfterGroup) -> Callable:
    """The scan body over a group of env times ``ts``: ``step`` at each, then ``after_group``.
    Returns the group's mean step metrics with the hook's, and the steps' outputs."""

    def group(c, ts):
        c, (m, out) = jax.lax.scan(step, c, ts)
        c, m_after = after_group(c)
        return c, ({**jax.tree.map(jnp.mean, m), **m_after}, out)

    return group


def train(step: Step, after_group: AfterGroup, carry: Any, horizon: int, group: int,
          high: High | None = None) -> tuple[Any, dict]:
    """One training episode of ``horizon`` env steps: ``step`` in groups of ``group`` steps
    with ``after_group`` after each, in ``high``'s subgoal periods where there is a high level.
    Returns the carry and the metrics, per group (no high level) or per period."""
    body = in_groups(step, after_group)
    if high is None:
        carry, (metrics, _) = jax.lax.scan(body, carry, period_times(0, horizon, group))
        return carry, metrics

    def period(c, p):
        low, context = high.choose(c, p)
        low, (m, out) = jax.lax.scan(body, low, period_times(p, high.period, group))
        return high.finish(c, low, context, p, m, out)

    return jax.lax.scan(period, carry, jnp.arange(horizon // high.period))


# --------------------------------------------------------------------------------------------
# Evaluation episodes
# --------------------------------------------------------------------------------------------


class Decision(NamedTuple):
    """What a policy does at one step of every env: the action ``[E, A]``, the goal the low
    level chases (a planner's waypoint, else the subgoal; ``[E, 2]``), the high level's
    subgoal (the final goal without one) and what the method reports of the step."""

    action: jax.Array
    target: jax.Array
    subgoal: jax.Array
    out: Any = None


#: A policy step: ``(memory, state, x) -> (memory, decision)``; ``memory`` is what the policy
#: keeps between steps (e.g. a waypoint follower), ``x`` the step's scanned input.
Policy = Callable[[Any, State, Any], tuple[Any, Decision]]
#: The high level at a period's start: ``state -> (policy, memory, xs, out)``, the low-level
#: policy of the period with its first memory and scanned inputs, and what the method reports
#: of the period.
Plan = Callable[[State], tuple[Policy, Any, Any, Any]]


def unroll(env: Env, s: State, policy: Policy, steps: int, *, xs: Any = None,
           memory: Any = None, trace: bool = False) -> tuple[State, Any, dict | None]:
    """``steps`` env steps of every episode in ``s`` by ``policy``: the last states, the
    decisions' ``out`` per step, and with ``trace`` each step's :func:`trace_step`."""

    def step(c, x):
        s, memory = c
        memory, d = policy(memory, s, x)
        rec = trace_step(s, d.target, d.subgoal) if trace else None
        return (jax.vmap(env.step)(s, d.action), memory), (d.out, rec)

    (s, _), (out, rec) = jax.lax.scan(step, (s, memory), xs, length=steps)
    return s, out, rec


def unroll_periods(env: Env, s: State, plan: Plan, steps: int, period: int, *,
                   trace: bool = False) -> tuple[State, tuple[Any, Any], dict | None]:
    """:func:`unroll` in periods of ``period`` steps, ``plan`` choosing each period's policy
    at its start. Returns the last states, ``(the plans' out, the steps' out)`` (leading axes
    ``[steps / period]`` and ``[steps / period, period]``) and the trace."""

    def one(s, _):
        policy, memory, xs, out = plan(s)
        s, steps_out, rec = unroll(env, s, policy, period, xs=xs, memory=memory, trace=trace)
        return s, ((out, steps_out), rec)

    s, (out, rec) = jax.lax.scan(one, s, None, length=steps // period)
    return s, out, rec


def start_states(env: Env, key: jax.Array, n: int) -> State:
    """``2n`` fresh episodes: the first ``n`` from the start towards ``env.maze.goal`` (the
    paper's evaluation), the other ``n`` towards goals drawn as in training; every field
    :func:`~flrjax.algos.common.batched`."""
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


def trace_step(s: State, target: jax.Array, subgoal: jax.Array) -> dict:
    """One step of every evaluation episode, as :func:`traced` keeps it: the torso's xy and
    whether it is fallen before the step, the goal the low level chases in it (``waypoint``:
    a planner's waypoint, else the subgoal) and the high level's subgoal (the final goal
    without one); for a MuJoCo body also its ``qpos``, to render the episode."""
    rec = {"xy": s.info["achieved_goal"], "fallen": s.info["fallen"], "waypoint": target,
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


def report(final: State, n: int, rec: dict | None, trace: bool, extra: dict | None = None):
    """An evaluation's result: :func:`final_metrics` of the ``final`` states with the
    method's ``extra`` metrics (``eval/`` names), and with ``trace`` the trace (:func:`traced`
    of the records ``rec``)."""
    metrics = {**final_metrics(final.info, n), **(extra or {})}
    return traced(metrics, rec, final, n) if trace else metrics
