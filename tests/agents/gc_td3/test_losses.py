"""Tests for flrjax.agents.gc_td3.losses: the critic targets against a NumPy forward pass, and
the fixed points of the two readings of the low level's value on a chain."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import rewards
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value, losses
from flrjax.agents.gc_td3.networks import critic_outputs, policy, q_from_output
from tests.agents.gc_td3.common import (
    CFG,
    HP,
    OBS,
    A,
    B,
    G,
    bandit_batch,
    critic_g_target,
    critic_target,
    new_state,
    np_mlp,
    np_policy,
    np_q,
)


@pytest.mark.parametrize("critic", ["critic", "critic_g"])
def test_critic_target_matches_numpy(critic):
    """y = r + gamma * min_i Q'_i(s', pi'(s', g) + noise, g), clipped as learn.py clips."""
    s = new_state()
    # make targets differ from the online nets, so the test sees which ones are used
    s = s.replace(**{f: getattr(s, f).replace(target_params=jax.tree.map(
        lambda p: np.asarray(p) * 1.5, getattr(s, f).target_params))
        for f in ("actor", "critic", "critic_g")})
    batch = bandit_batch(np.random.default_rng(0))
    batch["next_obs"] = batch["obs"][::-1].copy()
    batch["reward"][:5] = -200.0  # below -clip_return
    batch["reward"][5:10] = 5.0  # above 0
    key = jax.random.key(4)
    target_fn = critic_target if critic == "critic" else critic_g_target
    y = np.asarray(target_fn(s, batch, key))

    noise = HP.target_noise * np.asarray(jax.random.normal(key, (B, A)))
    next_a = np_policy(s.actor.target_params, batch["next_obs"], batch["goal"]) + noise
    twin = getattr(s, critic).target_params
    q_next = np.minimum(*(np_q(twin, i, batch["next_obs"], batch["goal"], next_a)
                          for i in range(2)))
    want = batch["reward"] + HP.gamma * q_next
    want = np.clip(want, -CFG.clip_return, 0.0) if critic == "critic" else np.minimum(want, 0.0)
    np.testing.assert_allclose(y, want, rtol=1e-4, atol=1e-5)
    assert np.all(y <= 0.0)
    if critic == "critic":
        assert np.all(y[:5] == -CFG.clip_return)
    else:
        assert np.all(y[:5] < -CFG.clip_return)  # the g-critics' target has no lower clip


def test_critic_target_stops_at_reached_transitions_with_reach_ends():
    """reach_ends: y = r where the batch's ``reached`` holds, r + gamma Q' elsewhere, clipped."""
    s = new_state()
    batch = bandit_batch(np.random.default_rng(1))
    batch["reached"] = np.arange(B) % 3 == 0
    key = jax.random.key(5)
    y_boot = np.asarray(critic_target(s, batch, key))
    ends = s.replace(config=dataclasses.replace(CFG, reach_ends=True))
    y_ends = np.asarray(critic_target(ends, batch, key))
    r = batch["reward"]
    np.testing.assert_array_equal(y_ends[batch["reached"]],
                                  np.clip(r, -CFG.clip_return, 0.0)[batch["reached"]])
    np.testing.assert_array_equal(y_ends[~batch["reached"]], y_boot[~batch["reached"]])
    assert not np.allclose(y_ends[batch["reached"]], y_boot[batch["reached"]])


def test_critic_target_of_an_n_step_batch_bootstraps_with_its_discount():
    """n_step: the main critics' y = r + discount * Q'(s'), with the batch's per-row
    ``discount`` (gamma ** steps) in place of gamma; the distance critics keep gamma."""
    s = new_state()
    batch = bandit_batch(np.random.default_rng(2))
    batch["reward"] = np.full(B, -0.1, np.float32)
    batch["discount"] = (HP.gamma ** (1 + np.arange(B) % 3)).astype(np.float32)
    key = jax.random.key(6)
    y_one = np.asarray(critic_target(s, batch, key))
    n_step = s.replace(config=dataclasses.replace(CFG, n_step=3))
    y_n = np.asarray(critic_target(n_step, batch, key))
    q_next = (y_one - batch["reward"]) / HP.gamma  # unclipped: Q' of these nets is > -80
    np.testing.assert_allclose(y_n, batch["reward"] + batch["discount"] * q_next, rtol=1e-5,
                               atol=1e-6)
    np.testing.assert_array_equal(np.asarray(critic_g_target(n_step, batch, key)),
                                  np.asarray(critic_g_target(s, batch, key)))


def _np_project(values: np.ndarray, probs: np.ndarray, atoms: np.ndarray) -> np.ndarray:
    """C51's projection by its definition: each clipped value's mass to the atom below and the
    atom above it, in proportion to its nearness to each."""
    out = np.zeros_like(probs)
    dz = atoms[1] - atoms[0]
    for b in range(values.shape[0]):
        for v, p in zip(np.clip(values[b], atoms[0], atoms[-1]), probs[b], strict=True):
            pos = (v - atoms[0]) / dz
            lo = min(int(np.floor(pos)), len(atoms) - 2)
            out[b, lo] += p * (lo + 1 - pos)
            out[b, lo + 1] += p * (pos - lo)
    return out


def _twins(params) -> list:
    """The two critics' parameters of a twin's, as NumPy arrays."""
    return [jax.tree.map(lambda p, i=i: np.asarray(p)[i], params) for i in range(2)]


def test_categorical_critic_target_and_loss_match_numpy():
    """critic_atoms: the target is the lower-mean target twin's distribution at
    (s', pi'(s', g) + noise), its atoms moved to r + gamma z (r alone where the transition
    ends) and projected back (C51); the loss is the twins' summed cross-entropy with it, and
    Q (also q_value's, the actor's and eq. 5's) the distribution's mean."""
    cfg = dataclasses.replace(CFG, critic_atoms=11, reach_ends=True)
    s = gc_td3.init(jax.random.key(0), OBS, G, A, cfg, HP)
    s = s.replace(**{f: getattr(s, f).replace(target_params=jax.tree.map(
        lambda p: np.asarray(p) * 1.5, getattr(s, f).target_params))
        for f in ("actor", "critic")})
    rng = np.random.default_rng(5)
    batch = bandit_batch(rng)
    batch["next_obs"] = batch["obs"][::-1].copy()
    batch["reward"] = rng.choice([-1.0, 0.0, -200.0, 5.0], B).astype(np.float32)
    batch["reached"] = np.arange(B) % 4 == 0
    key = jax.random.key(4)
    y = np.asarray(jax.jit(losses.critic_target)(s, batch, key))

    atoms = np.linspace(-cfg.clip_return, 0.0, 11)
    noise = HP.target_noise * np.asarray(jax.random.normal(key, (B, A)))
    next_a = np_policy(s.actor.target_params, batch["next_obs"], batch["goal"]) + noise
    x = np.concatenate([batch["next_obs"], batch["goal"], next_a / CFG.action_max], -1)
    logits = [np_mlp(twin, x) for twin in _twins(s.critic.target_params)]
    probs = [np.exp(z - z.max(-1, keepdims=True)) for z in logits]
    probs = [p / p.sum(-1, keepdims=True) for p in probs]
    lower = np.where((probs[0] @ atoms <= probs[1] @ atoms)[:, None], probs[0], probs[1])
    moved = batch["reward"][:, None] + np.where(batch["reached"], 0.0, HP.gamma)[:, None] * atoms
    want = _np_project(moved, lower, atoms)
    np.testing.assert_allclose(y, want, atol=1e-5)
    np.testing.assert_allclose(y.sum(-1), 1.0, rtol=1e-5)
    assert np.all(y[batch["reward"] == 5.0, -1] > 0)  # past the top atom: clipped to 0

    loss, q = losses.critic_loss(s.critic.params, s, batch, y)
    x = np.concatenate([batch["obs"], batch["goal"], batch["action"] / CFG.action_max], -1)
    online = [np_mlp(twin, x) for twin in _twins(s.critic.params)]
    log_p = [z - z.max(-1, keepdims=True) for z in online]
    log_p = [lp - np.log(np.exp(lp).sum(-1, keepdims=True)) for lp in log_p]
    np.testing.assert_allclose(float(loss), sum(-(y * lp).sum(-1).mean() for lp in log_p),
                               rtol=1e-4)
    means = np.stack([np.exp(lp) @ atoms for lp in log_p])
    np.testing.assert_allclose(np.asarray(q), means, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(
        np.asarray(gc_td3.q_value(s, batch["obs"], batch["goal"], batch["action"])),
        means.min(0), rtol=1e-4, atol=1e-4)
    assert s.critic.params["params"]["MLP_0"]["TorchDense_2"]["bias"].shape == (2, 11)
    assert s.critic_g.params["params"]["MLP_0"]["TorchDense_2"]["bias"].shape == (2, 1)
    with pytest.raises(ValueError, match="scalar critics"):  # eq. 5's kernel: XLA's only
        fused_value.value(s, batch["obs"], batch["goal"][:, None])


def _chain_fixed_point(alpha: float, gamma: float, m: int, depth: int, reach_ends: bool
                       ) -> np.ndarray:
    """V(d), d = 0..depth steps before a subgoal on a line walked one unit a step (staying once
    there), iterated to its fixed point with eq. 5's reward (:func:`rewards
    .forward_looking_reward`, the next subgoal m units past the reached one, read from the
    table) and :func:`losses.td_target`."""
    d = jnp.arange(depth + 1)
    x = depth - d  # the position; the subgoal sits at `depth`
    nxt = jnp.minimum(x + 1, depth).astype(jnp.float32)
    pos = jnp.stack([nxt, jnp.zeros_like(nxt)], -1)
    subgoal = jnp.broadcast_to(jnp.array([depth, 0.0]), pos.shape)
    candidates = (subgoal + jnp.array([m, 0.0]))[:, None]

    @jax.jit
    def sweep(v):
        def value_fn(obs, goals):  # V(s', sg') from the table: sg' is round(sg'_x - x') ahead
            return v[jnp.round(goals[..., 0] - obs[:, None, 0]).astype(jnp.int32)]

        out = rewards.forward_looking_reward(value_fn, pos, pos, subgoal, candidates,
                                             alpha=alpha, eps=float(m), delta=0.5)
        q_next = v[jnp.maximum(d - 1, 0)]
        return losses.td_target(out.reward, q_next, gamma, out.reached if reach_ends else None)

    v = jnp.zeros(depth + 1)
    for _ in range(3000):
        v = sweep(v)
    return np.asarray(v)


@pytest.mark.parametrize("reach_ends", [False, True])
@pytest.mark.parametrize("alpha", [0.0, 0.05, 0.1])
def test_each_reading_of_the_low_value_has_its_closed_form_fixed_point(alpha, reach_ends):
    """On a chain, with c(d) = (1 - gamma^(d-1)) / (1 - gamma) the cost of d - 1 unreached steps:
    reach_ends gives V(d) = -c(d) + gamma^(d-1) alpha V(m), so
    V(m) = -c(m) / (1 - alpha gamma^(m-1)); the infinite reading also pays alpha V(m) for every
    step spent on the reached subgoal (V(0) = alpha V(m) / (1 - gamma)), so
    V(m) = -(1 - gamma^(m-1)) / (1 - gamma - alpha gamma^(m-1)): -1 / (1 - gamma) at
    alpha = 1 - gamma, whatever m (the collapse of docs/results.md)."""
    gamma, m, depth = 0.9, 3, 6
    v = _chain_fixed_point(alpha, gamma, m, depth, reach_ends)
    d = np.arange(1, depth + 1)
    g = gamma ** (d - 1)
    c = (1 - g) / (1 - gamma)
    gm = gamma ** (m - 1)
    if reach_ends:
        v_m = -(1 - gm) / ((1 - gamma) * (1 - alpha * gm))
        want = -c + g * alpha * v_m
    else:
        v_m = -(1 - gm) / (1 - gamma - alpha * gm)
        want = -c + g * alpha * v_m / (1 - gamma)
        np.testing.assert_allclose(v[0], alpha * v_m / (1 - gamma), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(v[1:], want, rtol=1e-5, atol=1e-5)
    if np.isclose(alpha, 1 - gamma) and not reach_ends:
        np.testing.assert_allclose(v[1:], -1 / (1 - gamma), rtol=1e-5)


def _k_step_fixed_point(alpha: float, gamma: float, m: int, depth: int, k: int) -> np.ndarray:
    """V_h(d), h = 0..k steps left, d = 0..depth steps before the subgoal on the chain of
    :func:`_chain_fixed_point`, iterated with eq. 5's reward (the next subgoal's value read at
    a fresh horizon, V_k(m)) and :func:`losses.td_target` stopping after the last step."""
    d = jnp.arange(depth + 1)
    nxt = jnp.minimum(depth - d + 1, depth).astype(jnp.float32)
    pos = jnp.stack([nxt, jnp.zeros_like(nxt)], -1)
    subgoal = jnp.broadcast_to(jnp.array([depth, 0.0]), pos.shape)
    candidates = (subgoal + jnp.array([m, 0.0]))[:, None]

    @jax.jit
    def sweep(v):  # v[h, d]; v[0] = 0: no step left
        def value_fn(obs, goals):
            return v[k][jnp.round(goals[..., 0] - obs[:, None, 0]).astype(jnp.int32)]

        out = rewards.forward_looking_reward(value_fn, pos, pos, subgoal, candidates,
                                             alpha=alpha, eps=float(m), delta=0.5)
        h = jnp.arange(1, k + 1)[:, None]
        y = losses.td_target(out.reward, v[h - 1, jnp.maximum(d - 1, 0)], gamma, h - 1 == 0)
        return v.at[1:].set(y)

    v = jnp.zeros((k + 1, depth + 1))
    for _ in range(3000):
        v = sweep(v)
    return np.asarray(v)


@pytest.mark.parametrize("alpha", [0.0, 0.05, 0.1])
def test_the_k_step_value_has_its_closed_form_fixed_point(alpha):
    """The paper's V^l(s, sg) = E[sum of gamma^t r over the subgoal's steps] with h steps left
    (TD3Config.horizon): at d steps from the subgoal, h < d pays -c(h + 1); h >= d pays
    -c(d) + gamma^(d-1) alpha V* (1 - gamma^(h-d+1)) / (1 - gamma), alpha V* for each step
    from reaching to the horizon, with V* = V_k(m) =
    -(1 - gamma^(m-1)) / (1 - gamma - alpha gamma^(m-1) (1 - gamma^(k-m+1))): no collapse to
    -1 / (1 - gamma) at alpha = 1 - gamma."""
    gamma, m, depth, k = 0.9, 3, 6, 5
    v = _k_step_fixed_point(alpha, gamma, m, depth, k)
    gm = gamma ** (m - 1)
    v_star = -(1 - gm) / (1 - gamma - alpha * gm * (1 - gamma ** (k - m + 1)))
    want = np.zeros((k + 1, depth + 1))
    for h in range(1, k + 1):
        for d in range(depth + 1):
            if d == 0:  # on the subgoal: every step reaches it
                want[h, d] = alpha * v_star * (1 - gamma ** h) / (1 - gamma)
            elif h < d:
                want[h, d] = -(1 - gamma ** h) / (1 - gamma)
            else:
                want[h, d] = (-(1 - gamma ** (d - 1)) / (1 - gamma)
                              + gamma ** (d - 1) * alpha * v_star
                              * (1 - gamma ** (h - d + 1)) / (1 - gamma))
    np.testing.assert_allclose(v, want, rtol=1e-5, atol=1e-5)
    assert v[k, m] > -1 / (1 - gamma) + 1


def test_critic_target_with_a_horizon_reads_one_step_fewer_and_stops_at_the_last():
    """horizon k: y = r + gamma min Q'(s', pi'(s', g, h - 1), g, h - 1) for h = steps_left > 1,
    y = r at h = 1 (clipped as always); the networks read h / k as one more input."""
    cfg = dataclasses.replace(CFG, horizon=4)
    s = gc_td3.init(jax.random.key(0), OBS, G, A, cfg)
    batch = bandit_batch(np.random.default_rng(2))
    batch["next_obs"] = batch["obs"][::-1].copy()
    batch["steps_left"] = np.arange(B) % 4 + 1
    key = jax.random.key(6)
    y = np.asarray(critic_target(s, batch, key))
    left = batch["steps_left"] - 1
    next_a = policy(s, s.actor.target_params, batch["next_obs"], batch["goal"], None, left)
    next_a = next_a + s.hp.target_noise * jax.random.normal(key, next_a.shape)
    out = critic_outputs(s, s.critic.target_params, batch["next_obs"], batch["goal"], next_a,
                         None, left)
    boot = batch["reward"] + s.hp.gamma * np.asarray(jnp.min(q_from_output(out, cfg, s.hp), 0))
    want = np.clip(np.where(left == 0, batch["reward"], boot), -cfg.clip_return, 0.0)
    np.testing.assert_allclose(y, want, rtol=1e-5, atol=1e-6)
    full = policy(s, s.actor.params, batch["obs"], batch["goal"])
    assert np.array_equal(full, policy(s, s.actor.params, batch["obs"], batch["goal"], None,
                                       np.full(B, 4)))
    assert not np.allclose(full, policy(s, s.actor.params, batch["obs"], batch["goal"], None,
                                        np.full(B, 1)))
