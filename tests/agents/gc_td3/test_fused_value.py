"""Tests for flrjax.agents.gc_td3.fused_value: the fused kernel of eq. 5's candidate values
(run by Pallas's interpreter here; the GPU runs the same kernel through Triton)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value


def _agents(runs: int, obs: int, action: int, hidden: int, **cfg) -> gc_td3.AgentState:
    """Agents whose target networks differ from each other's and from the online ones."""
    td3 = gc_td3.TD3Config(hidden_sizes=(hidden,) * 3, **cfg)

    def one(key):
        k_init, k_t = jax.random.split(key)
        state = gc_td3.init(k_init, obs, 2, action, td3)
        leaves, tree = jax.tree.flatten(state.critic.target_params)
        keys = jax.random.split(k_t, len(leaves))
        moved = [x + 0.05 * jax.random.normal(k, x.shape) for k, x in zip(keys, leaves,
                                                                          strict=True)]
        state = state.replace(critic=state.critic.replace(
            target_params=jax.tree.unflatten(tree, moved)))
        if td3.obs_norm:  # statistics of observations far from the raw inputs' 0 and 1
            k_m, k_s = jax.random.split(k_t)
            state = state.replace(obs_stats=state.obs_stats.replace(
                mean=2.0 * jax.random.normal(k_m, (obs,)),
                std=jax.random.uniform(k_s, (obs,), minval=0.5, maxval=4.0)))
        return state

    return jax.vmap(one)(jax.random.split(jax.random.key(0), runs))


def _inputs(runs: int, b: int, m: int, obs: int) -> tuple[jax.Array, jax.Array]:
    k_o, k_g = jax.random.split(jax.random.key(1))
    next_obs = jax.random.normal(k_o, (runs, b, obs)).at[..., :2].multiply(6.0)
    return next_obs, next_obs[..., None, :2] + 2.5 * jax.random.normal(k_g, (runs, b, m, 2))


@pytest.mark.parametrize("cfg,cols", [({}, 32), ({}, 16),
                                      ({"dist_critic": False, "absolute_goal": True}, 32),
                                      ({"horizon": 8}, 32), ({"obs_norm": True}, 32)])
def test_fused_values_match_xla_bf16_values_under_a_vmap_over_runs(cfg, cols):
    """The kernel's V against gc_td3.value with the same bf16 operands, vmapped over 3 runs,
    on 5 x 7 = 35 rows (not a multiple of the 16-row block: padded and cut): every value
    within 1%, or 0.2% of the largest near 0 (bf16's rounding of an activation may land the
    other way: the critics' first product sums its two input parts apart, and 16-wide column
    chunks sum each product in parts), and no farther from float32's than XLA's bf16 values
    are, on average, up to 25%. With a horizon (the k-step value) both read a fresh goal:
    all its steps left; with --obs-norm both read the inputs normalised."""
    runs, b, m, obs, action = 3, 5, 7, 11, 3
    agents = _agents(runs, obs, action, 32, **cfg)
    next_obs, goals = _inputs(runs, b, m, obs)
    fused = jax.jit(jax.vmap(lambda a, o, g: fused_value.value(
        a, o, g, settings=fused_value.KernelSettings(block_rows=16, chunk_cols=cols))))(
        agents, next_obs, goals)
    bf16 = jax.vmap(lambda a, o, g: gc_td3.value(a, o, g, dot_dtype=jnp.bfloat16))(
        agents, next_obs, goals)
    f32 = jax.vmap(gc_td3.value)(agents, next_obs, goals)
    assert fused.shape == (runs, b, m)
    np.testing.assert_allclose(fused, bf16, rtol=1e-2, atol=2e-3 * float(jnp.abs(bf16).max()))
    assert float(jnp.abs(fused - f32).mean()) <= 1.25 * float(jnp.abs(bf16 - f32).mean())
    assert not np.allclose(fused[0], fused[1])  # each run its own networks


def test_supported_widths_are_powers_of_two_from_16():
    assert [h for h in (8, 16, 48, 64, 256, 300, 512) if fused_value.supported(h)] == [
        16, 64, 256, 512]


def test_the_default_kernel_is_fused_on_gpus_for_bf16_critics_without_layer_norm(monkeypatch):
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert fused_value.choose(None, "bfloat16", 256) == "fused"
    assert fused_value.choose(None, "bfloat16", 256, layer_norm=True) == "xla"
    assert fused_value.choose(None, "float32", 256) == "xla"
    assert fused_value.choose("fused", "bfloat16", 256, layer_norm=True) == "fused"  # as asked
    monkeypatch.setattr(jax, "default_backend", lambda: "cpu")
    assert fused_value.choose(None, "bfloat16", 256) == "xla"


def test_fused_values_skip_the_blocks_past_the_wanted_rows():
    """``rows`` per run under a vmap: the first ``rows`` transitions' values are those of the
    whole evaluation, and the blocks of kernel rows that start past ``rows * M`` are not
    computed (their raw outputs are the kernel's zeros)."""
    runs, b, m, obs, action, block = 2, 5, 7, 11, 3, 16
    agents = _agents(runs, obs, action, 32)
    next_obs, goals = _inputs(runs, b, m, obs)
    settings = fused_value.KernelSettings(block_rows=block, chunk_cols=32)
    rows = jnp.array([1, 3])  # kernel rows 7 and 21 wanted: blocks 0 and 0-1 of 3 are live

    def both(a, o, g, n):
        sub = fused_value.value(a, o, g, settings=settings, rows=n)
        o_b = jnp.broadcast_to(o[:, None], (b, m, obs))
        raw = fused_value.twin_outputs(a, a.actor.target_params, a.critic.target_params,
                                       o_b, g, settings=settings, wanted=n * m)
        return sub, raw.reshape(2, b * m)

    sub, raw = jax.jit(jax.vmap(both))(agents, next_obs, goals, rows)
    whole = jax.jit(jax.vmap(lambda a, o, g: fused_value.value(a, o, g, settings=settings)))(
        agents, next_obs, goals)
    for r, n in enumerate(rows.tolist()):
        np.testing.assert_array_equal(sub[r, :n], whole[r, :n])
        live = -(-n * m // block) * block
        assert np.all(np.asarray(raw[r, :, live:]) == 0.0)
        assert np.all(np.asarray(raw[r, :, :live]) != 0.0)


def test_fused_distances_with_a_horizon_match_xla_bf16_distances():
    """:func:`fused_value.distance` (DHRL's subgoal testing) of an agent with a horizon input
    against gc_td3.distance with the same bf16 operands: within 1% of the largest."""
    runs, b, obs, action = 2, 9, 11, 3
    agents = _agents(runs, obs, action, 32, horizon=8)
    next_obs, goals = _inputs(runs, b, 1, obs)
    settings = fused_value.KernelSettings(block_rows=16, chunk_cols=32)
    fused = jax.jit(jax.vmap(lambda a, o, g: fused_value.distance(a, o, g, settings=settings)))(
        agents, next_obs, goals[:, :, 0])
    bf16 = jax.vmap(lambda a, o, g: gc_td3.distance(a, o, g, dot_dtype=jnp.bfloat16))(
        agents, next_obs, goals[:, :, 0])
    assert fused.shape == (runs, b)
    np.testing.assert_allclose(fused, bf16, rtol=1e-2, atol=1e-2 * float(jnp.abs(bf16).max()))
