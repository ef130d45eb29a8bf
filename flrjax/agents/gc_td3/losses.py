"""Losses of goal-conditioned TD3: critic targets, the twin-critic loss, the actor loss.

learn.py ``LowLearner``: ``critic_loss`` (main critics), ``critic_loss_g`` (distance critics)
and ``actor_loss``. The losses take the parameters they differentiate; the agent's state
supplies the other networks (the targets, the critic the actor climbs), the config and the
traced hyperparameters (``state.hp``). A
method adds its own actor term through :data:`ActorExtra` (HIGL's landmark loss, PIG's
imitation). Every network pass here has the matrix operands of ``config.train_precision``
(:func:`.networks.train_dot_dtype`), gradients included; a method's extra term keeps its own.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp

from flrjax.agents.gc_td3.networks import (
    Params,
    atom_values,
    critic_outputs,
    policy,
    q_from_output,
    train_dot_dtype,
    unit_action,
)
from flrjax.agents.gc_td3.state import AgentState

Array = jax.Array
Metrics = dict[str, Array]


def td_target(reward: Array, q_next: Array, gamma: Array | float, done: Array | None = None
              ) -> Array:
    """``r + gamma * Q'(s')``, or ``r`` alone where ``done``: the transition reaches its goal
    (:attr:`TD3Config.reach_ends`) or is the last of its horizon (:attr:`TD3Config.horizon`).
    ``done`` None: every transition bootstraps. ``gamma`` may be per row: an n-step batch's
    ``discount`` (:attr:`TD3Config.n_step`)."""
    if done is None:
        return reward + gamma * q_next
    return reward + jnp.where(done, 0.0, gamma * q_next)


def _next_outputs(state: AgentState, target_twin: Params, batch: Mapping[str, Array],
                  key: Array, main: bool) -> tuple[Array, Array | None, Array | float]:
    """The target twin's raw outputs at ``(s', pi'(s', g) + noise, g)``, the transitions that
    end (None: none) and each row's discount, for :func:`_bootstrap`: the *target actor* with
    N(0, target_noise) smoothing noise, itself unclipped. By default no transition
    terminates: the reference bootstraps through every transition (goal-reaching never ends
    an episode). For the ``main`` critics, with :attr:`TD3Config.reach_ends` the batch's
    ``reached`` ones end; with a horizon, ``s'`` has one step fewer left and the last step
    ends (the batch's ``steps_left``); with :attr:`TD3Config.n_step` the main critics' batch
    is n steps long and bootstraps with its ``discount``."""
    cfg, hp, dtype = state.config, state.hp, train_dot_dtype(state.config)
    left = batch["steps_left"] - 1 if main and cfg.horizon is not None else None
    next_a = policy(state, state.actor.target_params, batch["next_obs"], batch["goal"], dtype,
                    left)
    next_a = next_a + hp.target_noise * jax.random.normal(key, next_a.shape, next_a.dtype)
    out = critic_outputs(state, target_twin, batch["next_obs"], batch["goal"], next_a, dtype,
                         left, distance_critics=not main)
    done = (batch["reached"] if main and cfg.reach_ends else
            left == 0 if left is not None else None)
    gamma = batch["discount"] if main and cfg.n_step > 1 else hp.gamma
    return out, done, gamma


def _bootstrap(state: AgentState, target_twin: Params, batch: Mapping[str, Array],
               key: Array, main: bool = False) -> Array:
    """:func:`td_target` with ``Q' = min_i Q'_i(s', pi'(s', g) + noise, g)`` ``[B]``, unclipped
    (:func:`_next_outputs`)."""
    out, done, gamma = _next_outputs(state, target_twin, batch, key, main)
    q_next = jnp.min(q_from_output(out, state.config, state.hp, not main), axis=0)
    return td_target(batch["reward"], q_next, gamma, done)


def project(values: Array, probs: Array, atoms: Array) -> Array:
    """C51's projection (Bellemare et al. 2017, Algorithm 1): the distribution ``probs[B, K]``
    on ``values[B, K]`` moved onto the evenly spaced ``atoms[K]``, each value's mass split
    between its two nearest atoms in proportion to nearness (values outside the atoms'
    range clipped to it)."""
    spacing = atoms[1] - atoms[0]
    values = jnp.clip(values, atoms[0], atoms[-1])
    weight = jnp.clip(1.0 - jnp.abs(values[:, :, None] - atoms) / spacing, 0.0, 1.0)
    return jnp.einsum("bk,bkj->bj", probs, weight)


def _categorical_target(state: AgentState, batch: Mapping[str, Array], key: Array) -> Array:
    """The main critics' target distribution ``[B, K]`` with :attr:`TD3Config.critic_atoms`:
    the target twin whose expected value is the lower (TD3's min, per transition), its
    atoms moved by :func:`td_target` (to the reward alone where the transition ends) and
    projected back onto the atoms (:func:`project`)."""
    cfg = state.config
    out, done, gamma = _next_outputs(state, state.critic.target_params, batch, key, True)
    probs = jax.nn.softmax(out.astype(jnp.float32), axis=-1)  # [2, B, K]
    atoms = atom_values(cfg)
    q = probs @ atoms
    lower = jnp.where((q[0] <= q[1])[:, None], probs[0], probs[1])
    gamma = jnp.broadcast_to(gamma, batch["reward"].shape)
    values = td_target(batch["reward"][:, None], atoms, gamma[:, None],
                       None if done is None else done[:, None])
    return project(values, lower, atoms)


def critic_target(state: AgentState, batch: Mapping[str, Array], key: Array) -> Array:
    """TD target of the main critics, clipped to ``[-clip_return, 0]`` (learn.py
    ``critic_loss``), from the target main critics; it stops at the batch's ``reached``
    transitions if :attr:`TD3Config.reach_ends`, after the last of the horizon if it has
    one. With :attr:`TD3Config.critic_atoms`, the target distribution ``[B, K]``
    (:func:`_categorical_target`)."""
    if state.config.critic_atoms:
        return jax.lax.stop_gradient(_categorical_target(state, batch, key))
    y = _bootstrap(state, state.critic.target_params, batch, key, main=True)
    return jax.lax.stop_gradient(jnp.clip(y, -state.config.clip_return, 0.0))


def critic_g_target(state: AgentState, batch_g: Mapping[str, Array], key: Array) -> Array:
    """TD target of the distance critics, clipped to ``<= 0`` only (learn.py
    ``critic_loss_g``), from the target distance critics."""
    y = _bootstrap(state, state.critic_g.target_params, batch_g, key)
    return jax.lax.stop_gradient(jnp.minimum(y, 0.0))


def critic_loss(
    twin_params: Params, state: AgentState, batch: Mapping[str, Array], target: Array,
    distance_critics: bool = False,
) -> tuple[Array, Array]:
    """Sum over the twins of ``mean((Q_i(s, a, g) - y)**2)``; also returns ``Q [2, B]``.

    The reference steps two Adams on the two losses; one Adam on the summed loss over both
    parameter sets is the same update (Adam is per parameter, the gradients do not mix).
    A categorical main critic (:attr:`TD3Config.critic_atoms`; ``target`` a distribution
    ``[B, K]``): the sum over the twins of the mean cross-entropy of its logits with it.
    """
    out = critic_outputs(state, twin_params, batch["obs"], batch["goal"], batch["action"],
                         train_dot_dtype(state.config), batch.get("steps_left"),
                         distance_critics)
    q = q_from_output(out, state.config, state.hp, distance_critics)
    if state.config.critic_atoms and not distance_critics:
        log_p = jax.nn.log_softmax(out.astype(jnp.float32), axis=-1)
        return -jnp.sum(jnp.mean(jnp.sum(target * log_p, axis=-1), axis=-1)), q
    return jnp.sum(jnp.mean(jnp.square(q - target), axis=-1)), q


ActorExtra = Callable[["AgentState", Params, Array, Mapping[str, Array]],
                      tuple[Array, Metrics]]
"""``extra(state, actor_params, pi[B, A], batch) -> (term, metrics)``: a method's own term
added to the actor loss (HIGL's landmark loss, PIG's imitation), with metrics of its own.
``actor_params`` are the ones being differentiated, ``pi = pi(s, g)`` on the batch."""


def actor_loss(
    actor_params: Params,
    state: AgentState,
    batch: Mapping[str, Array],
    extra: ActorExtra | None = None,
) -> tuple[Array, Metrics]:
    """``-mean Q_1(s, pi(s, g), g) + action_l2 * mean((pi / action_max)**2)`` [+ extra].

    learn.py ``LowLearner.actor_loss``: the first main critic only (agent.py ``forward1``),
    the L2 mean over batch *and* action dimensions. No BC term (it is only logged there).
    """
    cfg, dtype = state.config, train_dot_dtype(state.config)
    left = batch.get("steps_left")
    pi = policy(state, actor_params, batch["obs"], batch["goal"], dtype, left)
    out = critic_outputs(state, state.critic.params, batch["obs"], batch["goal"], pi, dtype,
                         left)
    q_pi = q_from_output(out[0], cfg, state.hp)
    l2 = jnp.mean(jnp.square(unit_action(pi, cfg)))
    loss = -jnp.mean(q_pi) + state.hp.action_l2 * l2
    metrics = {"q_pi": jnp.mean(q_pi), "action_l2": l2}
    if extra is not None:
        term, extra_metrics = extra(state, actor_params, pi, batch)
        loss = loss + term
        metrics = {**metrics, "actor_extra": term, **extra_metrics}
    return loss, metrics
