"""Networks, inputs and critic parametrisation of goal-conditioned TD3 (DHRL's low level).

The actor and the critics are ``flrjax.networks`` MLPs (core.py ``Actor``, ``Critic``); this
module says what goes into them (agent.py ``LowAgent._process_inputs_*``) and what a critic's
output means (agent.py ``DistCritic``: a distance, or ``DistReverseCritic``: Q itself). The
file names are those of the package docstring (:mod:`flrjax.agents.gc_td3`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from flrjax import networks
from flrjax.agents.gc_td3.state import AgentState, Hparams, Params, TD3Config

Array = jax.Array

class TD3Networks(NamedTuple):
    actor: networks.Actor
    critic: networks.Critic  # the main critics (categorical with ``critic_atoms``)
    critic_g: networks.Critic  # the distance critics: always scalar


def make_networks(config: TD3Config, action_size: int, dot_dtype: Any = None) -> TD3Networks:
    """Actor ``tanh(.) * action_max + action_offset`` and scalar critics, 3x256 ReLU (core.py);
    the main critics categorical with :attr:`TD3Config.critic_atoms`.

    ``dot_dtype`` (e.g. ``jnp.bfloat16``) rounds the layers' matrix operands, in the forward
    pass and its gradients (:class:`networks.TorchDense`); the parameters are the same either
    way. The updates pass :func:`train_dot_dtype`."""
    return TD3Networks(
        actor=networks.Actor(action_size, config.hidden_sizes, scale=config.action_max,
                             offset=config.action_offset, dot_dtype=dot_dtype),
        critic=networks.Critic(config.hidden_sizes, dot_dtype=dot_dtype,
                               layer_norm=config.critic_layer_norm, atoms=config.critic_atoms),
        critic_g=networks.Critic(config.hidden_sizes, dot_dtype=dot_dtype,
                                 layer_norm=config.critic_layer_norm),
    )


def train_dot_dtype(config: TD3Config) -> Any:
    """``dot_dtype`` of the passes inside an update (``config.train_precision``)."""
    return networks.dot_dtype(config.train_precision)


# Inputs (agent.py LowAgent._process_inputs_actor / _process_inputs_critic) ------------------


def state_size(config: TD3Config, obs_size: int) -> int:
    """Width of :func:`state_input`: the observation, and the steps left with a horizon."""
    return obs_size + (config.horizon is not None)


def state_input(config: TD3Config, obs: Array, steps_left: Array | None = None,
                stats: Any = None) -> Array:
    """``obs`` (normalised by ``stats``, :attr:`AgentState.obs_stats`, where given), with
    ``steps_left / horizon`` appended where the config has a horizon (``steps_left`` None: a
    fresh goal, 1)."""
    if stats is not None:
        obs = (obs - stats.mean) / stats.std
    if config.horizon is None:
        return obs
    frac = (jnp.ones(obs.shape[:-1], obs.dtype) if steps_left is None else
            jnp.broadcast_to(steps_left / config.horizon, obs.shape[:-1]).astype(obs.dtype))
    return jnp.concatenate([obs, frac[..., None]], axis=-1)


def goal_input(obs: Array, goal: Array, relative: bool, stats: Any = None) -> Array:
    """``goal - obs[:g]`` (``relative``) or ``goal``, normalised as :func:`state_input`
    normalises the observation's first ``g`` entries, the achieved goal (``stats`` None: raw;
    a difference is only scaled)."""
    g = goal.shape[-1]
    x = goal - obs[..., :g] if relative else goal
    if stats is None:
        return x
    return (x if relative else x - stats.mean[:g]) / stats.std[:g]


def actor_input(config: TD3Config, obs: Array, goal: Array, steps_left: Array | None = None,
                stats: Any = None) -> Array:
    """``[obs, goal - obs[:g]]`` (relative goal; ``[obs, goal]`` with ``absolute_goal``), the
    observation as :func:`state_input` gives it and the goal as :func:`goal_input` does.

    The reference's achieved goal is ``obs[:g]`` (the ant's torso x, y lead its observation).
    No input normalisation unless ``stats`` (:attr:`TD3Config.obs_norm`): DHRL's LowAgent
    never uses its normalizer.py.
    """
    return jnp.concatenate([state_input(config, obs, steps_left, stats),
                            goal_input(obs, goal, not config.absolute_goal, stats)], axis=-1)


def critic_input(config: TD3Config, obs: Array, goal: Array, action: Array,
                 steps_left: Array | None = None, stats: Any = None) -> Array:
    """``[obs, goal, (action - offset) / action_max]``: absolute goal (agent.py), scaled action
    (core.py; agent.py ``HighAgent`` subtracts the subgoal offset), the observation as
    :func:`state_input` gives it and the goal as :func:`goal_input` does."""
    return jnp.concatenate([state_input(config, obs, steps_left, stats),
                            goal_input(obs, goal, False, stats),
                            unit_action(action, config)], axis=-1)


def unit_action(action: Array, config: TD3Config) -> Array:
    """Action mapped to ``[-1, 1]``: ``(action - action_offset) / action_max``."""
    return (action - jnp.asarray(config.action_offset)) / jnp.asarray(config.action_max)


def policy(state: AgentState, actor_params: Params, obs: Array, goal: Array,
           dot_dtype: Any = None, steps_left: Array | None = None) -> Array:
    """Deterministic action ``pi(obs, goal)`` in ``action_offset ± action_max`` (with a
    horizon, ``steps_left`` of the goal's; None: all)."""
    actor = make_networks(state.config, state.action_size, dot_dtype).actor
    return actor.apply(actor_params,
                       actor_input(state.config, obs, goal, steps_left, state.obs_stats))


def critic_outputs(
    state: AgentState, twin_params: Params, obs: Array, goal: Array, action: Array,
    dot_dtype: Any = None, steps_left: Array | None = None, distance_critics: bool = False,
) -> Array:
    """Raw outputs ``[2, ...]`` of a twin critic (a distance with ``dist_critic``, else Q;
    ``[2, ..., atoms]`` logits of the main critics with ``critic_atoms``);
    ``distance_critics``: ``twin_params`` are the distance critics'."""
    nets = make_networks(state.config, state.action_size, dot_dtype)
    critic = nets.critic_g if distance_critics else nets.critic
    x = critic_input(state.config, obs, goal, action, steps_left, state.obs_stats)
    return jax.vmap(critic.apply, in_axes=(0, None))(twin_params, x)


# Critic parametrisation (agent.py DistCritic / DistReverseCritic) ---------------------------


def atom_values(config: TD3Config) -> Array:
    """The values ``[critic_atoms]`` a categorical main critic puts probability on: evenly
    spaced on ``[-clip_return, 0]``, the range its TD target is clipped to."""
    return jnp.linspace(-config.clip_return, 0.0, config.critic_atoms)


def q_from_output(out: Array, config: TD3Config, hp: Hparams, distance_critics: bool = False
                  ) -> Array:
    """Q from a critic output: ``-(1 - gamma**d) / (1 - gamma)`` for a distance critic
    (agent.py ``DistCritic.forward``, written as ``expm1(d log gamma) / (1 - gamma)``); the
    expectation of the logits' distribution over :func:`atom_values` for a categorical main
    critic (``distance_critics`` False)."""
    if config.critic_atoms and not distance_critics:
        return jax.nn.softmax(out.astype(jnp.float32), axis=-1) @ atom_values(config)
    if not config.dist_critic:
        return out
    return jnp.expm1(out * jnp.log(hp.gamma)) / hp.one_minus_gamma


def distance_from_output(out: Array, config: TD3Config, hp: Hparams) -> Array:
    """Steps-to-goal from a critic output (agent.py ``get_dist``), before the twin min/clamp.

    DistCritic: the output itself. DistReverseCritic: ``log(1 + Q (1 - gamma)) / log gamma``
    with Q clamped to ``>= 1 / (gamma - 1) + 1``. ``q_offset`` adds 1 in both.
    """
    if config.dist_critic:
        dist = out
    else:
        q = jnp.maximum(out, 1.0 - 1.0 / hp.one_minus_gamma)
        dist = jnp.log1p(q * hp.one_minus_gamma) / jnp.log(hp.gamma)
    return dist + 1.0 if config.q_offset else dist
