"""Tests for flrjax.networks: MLP shapes, torch-like init, actor bounds, running normaliser."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import networks as N


def test_actor_critic_shapes_and_bounds():
    x = jax.random.normal(jax.random.key(0), (3, 5, 7)) * 100.0  # saturate tanh
    actor = N.Actor(4, (16, 16), scale=(2.0, 2.0, 1.0, 1.0), offset=(1.0, 0.0, 0.0, -3.0))
    critic = N.Critic((16, 16))

    @jax.jit
    def forward(key: jax.Array, x: jax.Array) -> tuple[jax.Array, jax.Array]:
        ka, kc = jax.random.split(key)
        a = actor.apply(N.init_params(actor, ka, x[0, 0]), x)
        return a, critic.apply(N.init_params(critic, kc, x[0, 0]), x)

    a, q = forward(jax.random.key(1), x)
    assert a.shape == (3, 5, 4) and q.shape == (3, 5)
    lo, hi = np.array([-1.0, -2.0, -1.0, -4.0]), np.array([3.0, 2.0, 1.0, -2.0])
    assert np.all(np.asarray(a) >= lo) and np.all(np.asarray(a) <= hi)
    assert np.abs(np.asarray(a) - (lo + hi) / 2).max() > 0.5  # not stuck at the offset


def test_init_params_is_torch_linear_init():
    """Same tree as module.init; every layer U(±1/sqrt(fan_in)) (torch.nn.Linear default)."""
    mlp = N.MLP((64, 32), 3)
    x = jnp.zeros((1, 50))
    params = jax.jit(lambda k: N.init_params(mlp, k, x))(jax.random.key(0))
    ref_shapes = jax.eval_shape(mlp.init, jax.random.key(0), x)
    assert jax.tree.structure(ref_shapes) == jax.tree.structure(params)
    assert jax.tree.map(np.shape, params) == jax.tree.map(np.shape, ref_shapes)
    # TorchDense's own initialisers (used by module.init) have the same bounds
    dense = jax.jit(N.TorchDense(8).init)(jax.random.key(1), jnp.zeros((1, 50)))["params"]
    for name in ("kernel", "bias"):
        assert 0.5 * 50**-0.5 < np.abs(np.asarray(dense[name])).max() <= 50**-0.5 + 1e-7
    for layer, fan_in in (("TorchDense_0", 50), ("TorchDense_1", 64), ("TorchDense_2", 32)):
        for name in ("kernel", "bias"):
            w = np.asarray(params["params"][layer][name])
            assert np.abs(w).max() <= fan_in**-0.5 + 1e-7
        w = np.asarray(params["params"][layer]["kernel"])
        # uniform on ±b has std b / sqrt(3)
        np.testing.assert_allclose(w.std(), fan_in**-0.5 / np.sqrt(3.0), rtol=0.1)
    layers = params["params"]
    assert not np.allclose(layers["TorchDense_0"]["kernel"][:32, :32],
                           layers["TorchDense_1"]["kernel"][:32, :32])


def _reference_stats(chunks: list[np.ndarray], eps: float = 1e-2) -> tuple[np.ndarray, ...]:
    """DHRL normalizer.py with recompute_stats: float64 sums, count starting at 1."""
    total = np.concatenate(chunks, axis=0).astype(np.float64)
    count = 1.0 + total.shape[0]
    mean = total.sum(0) / count
    std = np.sqrt(np.maximum(eps**2, (total**2).sum(0) / count - mean**2))
    return mean, std


def test_normalizer_matches_numpy_with_clipping():
    rng = np.random.default_rng(0)
    scale = np.array([1.0, 10.0, 0.001], np.float32)  # the last one hits the eps floor
    a = (rng.normal(size=(200, 3)) * scale + [3.0, -5.0, 0.0]).astype(np.float32)
    b = (rng.normal(size=(7, 11, 3)) * scale + [3.0, -5.0, 0.0]).astype(np.float32)
    update = jax.jit(N.normalizer_update)
    state = N.normalizer_init(3)
    state = update(state, a)
    state = update(state, b.reshape(-1, 3)[:70])  # leading axes are flattened: use both forms
    state = update(state, b.reshape(-1, 3)[70:].reshape(1, 7, 3))
    mean, std = _reference_stats([a, b.reshape(-1, 3)])
    np.testing.assert_allclose(state.mean, mean, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(N.normalizer_std(state), std, rtol=1e-4)
    assert np.asarray(N.normalizer_std(state))[2] == np.float32(1e-2)

    x = np.array([[3.0, -5.0, 0.0], [1e3, -1e3, 1.0]], np.float32)
    want = np.clip((x - mean) / std, -5.0, 5.0)
    np.testing.assert_allclose(N.normalize(state, x, clip_range=5.0), want, rtol=1e-4,
                               atol=1e-5)
    assert np.abs(np.asarray(N.normalize(state, x, clip_range=5.0))).max() == 5.0


def test_normalizer_mask_and_large_offsets():
    """Masked samples are ignored; a large mean does not cancel the variance in float32."""
    rng = np.random.default_rng(1)
    x = (1e4 + rng.normal(size=(500, 2))).astype(np.float32)
    mask = rng.random(500) < 0.5
    state = N.normalizer_init(2)
    update = jax.jit(N.normalizer_update)
    for chunk, m in zip(np.split(x, 5), np.split(mask, 5), strict=True):
        state = update(state, chunk, m)
    mean, std = _reference_stats([x[mask].astype(np.float64)])
    np.testing.assert_allclose(state.count, 1 + mask.sum())
    np.testing.assert_allclose(state.mean, mean, rtol=1e-6)
    # the phantom zero sample dominates the spread: std ~ 1e4 / sqrt(n)
    np.testing.assert_allclose(N.normalizer_std(state), std, rtol=1e-3)
