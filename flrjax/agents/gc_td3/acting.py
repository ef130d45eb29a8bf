"""Acting and reading the critics: actions, Q values, values (the FLR's ``V``) and distances
(the planner's edge weights), from an :class:`~flrjax.agents.gc_td3.state.AgentState`."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from flrjax.agents.gc_td3.networks import (
    critic_outputs,
    distance_from_output,
    policy,
    q_from_output,
)
from flrjax.agents.gc_td3.state import AgentState, NetworkState

Array = jax.Array


def act(
    state: AgentState,
    obs: Array,
    goal: Array,
    key: Array,
    *,
    explore: bool | Array,
    steps_left: Array | None = None,
) -> Array:
    """Action ``[..., A]`` in ``action_offset ± action_max`` for ``obs[..., o]``, ``goal[..., g]``.

    With ``explore`` (algo.py ``Algo.get_actions``): ``pi + noise_eps * action_max * N(0, 1)``,
    clipped, then replaced, with probability ``random_eps`` per action vector, by a uniform
    random action. Without: ``pi`` (algo.py ``eval_get_actions``). ``explore`` may be traced,
    a scalar or one flag per row (shape ``obs.shape[:-1]``, e.g. train vs eval envs).
    ``steps_left``: of the goal's horizon, if the agent has one (None: all).
    """
    cfg, hp = state.config, state.hp
    a_max, offset = jnp.asarray(cfg.action_max), jnp.asarray(cfg.action_offset)
    pi = policy(state, state.actor.params, obs, goal, steps_left=steps_left)
    k_noise, k_rand, k_mask = jax.random.split(key, 3)
    noisy = pi + hp.noise_eps * a_max * jax.random.normal(k_noise, pi.shape, pi.dtype)
    noisy = jnp.clip(noisy, offset - a_max, offset + a_max)
    rand = offset + jax.random.uniform(k_rand, pi.shape, pi.dtype, -1.0, 1.0) * a_max
    use_rand = jax.random.bernoulli(k_mask, hp.random_eps, pi.shape[:-1])[..., None]
    explored = jnp.where(use_rand, rand, noisy)
    explore = jnp.asarray(explore)
    explore = explore[..., None] if explore.ndim else explore  # per-row flag [...] -> [..., 1]
    return jnp.where(explore, explored, pi)


def _params(net: NetworkState, target: bool) -> Any:
    return net.target_params if target else net.params


def q_value(
    state: AgentState,
    obs: Array,
    goal: Array,
    action: Array | None = None,
    *,
    target: bool = False,
    distance_critics: bool = False,
    dot_dtype: Any = None,
) -> Array:
    """``min_i Q_i(s, a, g)`` ``[...]`` of the main twin critics (``state.critic``; with
    ``distance_critics`` the distance critics, ``state.critic_g``), with ``a = pi(s, g)``
    when ``action`` is None (agent.py ``get_qs(net=0)`` / ``forward``). ``target``: the target
    networks. ``dot_dtype``: see :func:`networks.make_networks`."""
    critic = state.critic_g if distance_critics else state.critic
    if action is None:
        action = policy(state, _params(state.actor, target), obs, goal, dot_dtype)
    out = critic_outputs(state, _params(critic, target), obs, goal, action, dot_dtype,
                         distance_critics=distance_critics)
    return jnp.min(q_from_output(out, state.config, state.hp, distance_critics), axis=0)


def value(
    state: AgentState,
    obs: Array,
    goals: Array,
    *,
    dot_dtype: Any = None,
) -> Array:
    """``V(s, g) = min_i Q_i(s, pi(s, g), g)`` of every goal: ``obs[..., o]``, ``goals[..., M, g]``
    -> ``[..., M]``.

    Matches ``rewards.ValueFn`` (``functools.partial(value, state)``) for the forward-looking
    reward's ``V_l(s', sg')``: the *target* main critics and actor, the stable
    estimate TD learning bootstraps from. Not clipped (a distance critic can give Q > 0 where
    it predicts d < 0). ``dot_dtype=jnp.bfloat16`` evaluates it with bf16 matrix operands
    (the FLR's candidate values: a label, read through a max).
    """
    obs_b = jnp.broadcast_to(obs[..., None, :], goals.shape[:-1] + obs.shape[-1:])
    return q_value(state, obs_b, goals, target=True, dot_dtype=dot_dtype)


def distance(state: AgentState, obs: Array, goal: Array, dot_dtype: Any = None) -> Array:
    """Planner distance ``max(min(d_1, d_2), 0)`` ``[...]`` from the distance critics.

    agent.py ``LowAgent._get_dist_*``: the *online* ``critic1_g/2_g`` at ``a = pi(s, g)`` (online
    actor), each converted by :func:`networks.distance_from_output` (``get_dist``, ``q_offset``
    included), min over the twin, clamped at 0. ``functools.partial(distance, state)`` is a
    ``planner.DistFn``. ``dot_dtype``: see :func:`networks.make_networks` (DHRL's subgoal
    testing: a threshold on the nearest landmark's distance).
    """
    action = policy(state, state.actor.params, obs, goal, dot_dtype)
    out = critic_outputs(state, state.critic_g.params, obs, goal, action, dot_dtype,
                         distance_critics=True)
    dist = distance_from_output(out, state.config, state.hp)
    return jnp.maximum(jnp.min(dist, axis=0), 0.0)
