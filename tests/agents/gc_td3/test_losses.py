"""Tests for flrjax.agents.gc_td3.losses: the critic targets against a NumPy forward pass."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from tests.agents.gc_td3.common import (
    CFG,
    A,
    B,
    bandit_batch,
    critic_g_target,
    critic_target,
    new_state,
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

    noise = CFG.target_noise * np.asarray(jax.random.normal(key, (B, A)))
    next_a = np_policy(s.actor.target_params, batch["next_obs"], batch["goal"]) + noise
    twin = getattr(s, critic).target_params
    q_next = np.minimum(*(np_q(twin, i, batch["next_obs"], batch["goal"], next_a)
                          for i in range(2)))
    want = batch["reward"] + CFG.gamma * q_next
    want = np.clip(want, -CFG.clip_return, 0.0) if critic == "critic" else np.minimum(want, 0.0)
    np.testing.assert_allclose(y, want, rtol=1e-4, atol=1e-5)
    assert np.all(y <= 0.0)
    if critic == "critic":
        assert np.all(y[:5] == -CFG.clip_return)
    else:
        assert np.all(y[:5] < -CFG.clip_return)  # the g-critics' target has no lower clip
