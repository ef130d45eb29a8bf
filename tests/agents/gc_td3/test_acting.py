"""Tests for flrjax.agents.gc_td3.acting: actions, exploration, Q values, values, distances."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from flrjax.agents import gc_td3
from tests.agents.gc_td3.common import (
    CFG,
    HP,
    OBS,
    A,
    G,
    act,
    new_state,
    np_mlp,
    np_policy,
    np_q,
)


def test_act_shapes_bounds_and_explore():
    s = new_state()
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(3, 50, OBS)).astype(np.float32)
    goal = rng.normal(size=(3, 50, G)).astype(np.float32)
    key = jax.random.key(1)
    # one compile: per-row explore flags (shape [3, 50]); the scalar form is used below
    rows = np.ones((3, 50), bool)
    pi = np.asarray(act(s, obs, goal, key, explore=~rows))
    assert pi.shape == (3, 50, A)
    want = np_policy(s.actor.params, obs.reshape(-1, OBS), goal.reshape(-1, G))
    np.testing.assert_allclose(pi, want.reshape(3, 50, A), rtol=1e-4, atol=1e-5)
    noisy = np.asarray(act(s, obs, goal, key, explore=rows))
    assert noisy.shape == (3, 50, A) and np.abs(noisy).max() <= CFG.action_max
    assert not np.allclose(noisy, pi)
    per_row = np.arange(50) % 2 == 0  # explore in every other env only
    mixed = np.asarray(act(s, obs, goal, key, explore=np.broadcast_to(per_row, (3, 50))))
    np.testing.assert_array_equal(mixed[:, per_row], noisy[:, per_row])
    np.testing.assert_array_equal(mixed[:, ~per_row], pi[:, ~per_row])


def test_random_action_probability_and_noise_scale():
    s = new_state()
    rng = np.random.default_rng(0)
    n = 20000
    obs = (0.1 * rng.normal(size=(n, OBS))).astype(np.float32)
    goal = (0.1 * rng.normal(size=(n, G))).astype(np.float32)
    pi = np_policy(s.actor.params, obs, goal).astype(np.float32)
    assert np.abs(pi).max() < 0.7  # so the 0.1 Gaussian noise is (almost) never clipped
    only_random = s.replace(hp=s.hp.replace(noise_eps=jnp.float32(0.0)))
    a = np.asarray(act(only_random, obs, goal, jax.random.key(2), explore=True))
    np.testing.assert_allclose(  # and explore=False (a scalar flag) is the policy
        act(only_random, obs, goal, jax.random.key(2), explore=False), pi,
        rtol=1e-4, atol=1e-5)
    replaced = np.any(np.abs(a - pi) > 1e-5, axis=-1)
    assert abs(replaced.mean() - HP.random_eps) < 0.015  # 4 sigma at n = 20000
    # the replacements are uniform on [-1, 1]: mean 0, std 1/sqrt(3)
    np.testing.assert_allclose(a[replaced].std(), 3**-0.5, rtol=0.05)
    only_noise = s.replace(hp=s.hp.replace(random_eps=jnp.float32(0.0)))
    a = np.asarray(act(only_noise, obs, goal, jax.random.key(3), explore=True))
    np.testing.assert_allclose((a - pi).std(), HP.noise_eps * CFG.action_max, rtol=0.03)


def test_value_q_value_and_distance():
    s = new_state()
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(5, OBS)).astype(np.float32)
    goals = rng.normal(size=(5, 3, G)).astype(np.float32)

    @jax.jit
    def inference(s: gc_td3.AgentState, obs: jax.Array, goals: jax.Array):
        return (gc_td3.value(s, obs, goals), gc_td3.q_value(s, obs, goals[:, 1], target=True),
                gc_td3.distance(s, obs, goals[:, 0]))

    v, q1, d = (np.asarray(x) for x in inference(s, obs, goals))
    assert v.shape == (5, 3) and q1.shape == (5,) and d.shape == (5,)
    np.testing.assert_allclose(q1, v[:, 1], rtol=1e-6)
    for m in range(3):  # V(s, g) = min_i Q'_i(s, pi'(s, g), g) (target nets by default)
        a = np_policy(s.actor.target_params, obs, goals[:, m])
        want = np.minimum(*(np_q(s.critic.target_params, i, obs, goals[:, m], a)
                            for i in range(2)))
        np.testing.assert_allclose(v[:, m], want, rtol=1e-4, atol=1e-5)

    # distance: online actor and online g-critics, raw outputs, min over twins, clamped at 0
    a = np_policy(s.actor.params, obs, goals[:, 0])
    raw = [np_mlp(jax.tree.map(lambda p, i=i: np.asarray(p)[i], s.critic_g.params),
                  np.concatenate([obs, goals[:, 0], a], axis=-1))[:, 0] for i in range(2)]
    np.testing.assert_allclose(d, np.maximum(np.minimum(*raw), 0.0), rtol=1e-4, atol=1e-5)
