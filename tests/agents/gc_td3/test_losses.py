"""Tests for flrjax.agents.gc_td3.losses: the critic targets against a NumPy forward pass, and
the fused kernel's targets against XLA's."""

from __future__ import annotations

import dataclasses

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


@pytest.mark.parametrize("critic", ["critic", "critic_g"])
def test_fused_target_kernel_matches_xla_bf16_targets_with_the_same_noise(critic):
    """With bf16 updates the TD target's target actor and critics may run in the fused kernel
    (``target_kernel`` "fused"), the smoothing noise added inside it. Per-dimension action
    bounds and offsets (the high level's) and a noise large enough to move the targets: the
    fused targets agree with XLA's bf16 ones within bf16's rounding (1% of the targets'
    scale), lie no farther from float32's on average (up to 25%), and are far closer to them
    than targets without the noise are."""
    cfg = dataclasses.replace(CFG, action_max=(2.0, 0.5), action_offset=(1.0, -1.0),
                              target_noise=0.3, clip_return=1e3)
    s = new_state().replace(config=cfg)
    s = s.replace(**{f: getattr(s, f).replace(target_params=jax.tree.map(
        lambda p: np.asarray(p) * 1.5, getattr(s, f).target_params))
        for f in ("actor", "critic", "critic_g")})
    batch = bandit_batch(np.random.default_rng(0))
    batch["next_obs"] = batch["obs"][::-1].copy()
    key = jax.random.key(4)
    target_fn = critic_target if critic == "critic" else critic_g_target

    def target(**changes):
        return np.asarray(target_fn(s.replace(config=dataclasses.replace(cfg, **changes)),
                                    batch, key))

    f32 = target()
    xla = target(train_precision="bfloat16")
    fused = target(train_precision="bfloat16", target_kernel="fused")
    quiet = target(train_precision="bfloat16", target_kernel="fused", target_noise=0.0)
    scale = float(np.abs(f32).max())
    np.testing.assert_allclose(fused, xla, rtol=1e-2, atol=1e-2 * scale)
    assert np.abs(fused - f32).mean() <= 1.25 * np.abs(xla - f32).mean()
    assert np.abs(quiet - f32).mean() > 5 * np.abs(fused - f32).mean()


def test_the_fused_target_kernel_needs_bf16_updates():
    with pytest.raises(ValueError, match="needs train_precision 'bfloat16'"):
        dataclasses.replace(CFG, target_kernel="fused")
