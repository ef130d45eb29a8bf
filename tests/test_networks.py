"""Tests for flrjax.networks: MLP shapes, torch-like init, actor bounds, bf16 products."""

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


def test_low_precision_dot_multiplies_rounded_operands_forward_and_backward():
    """Output and both gradients are products of bf16-rounded operands (the cotangent rounded
    too), accumulated and returned in float32: float64 products of the rounded values, to
    float32 accumulation. Twin kernels on one shared input (vmap batches the kernel, not the
    input), as the twin critics' first layer."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(32, 8)).astype(np.float32)
    k = rng.normal(size=(2, 8, 16)).astype(np.float32)
    w = rng.normal(size=(2, 32, 16)).astype(np.float32)  # the cotangent d loss / d out

    def out(x, k):
        return jax.vmap(lambda kk: N.low_precision_dot(x, kk, jnp.bfloat16))(k)

    dx, dk = jax.jit(jax.grad(lambda x, k: jnp.sum(out(x, k) * w), argnums=(0, 1)))(x, k)
    assert out(x, k).dtype == dx.dtype == dk.dtype == jnp.float32

    def r(a):  # rounded to bf16, as float64
        return np.asarray(jnp.asarray(a).astype(jnp.bfloat16)).astype(np.float64)

    np.testing.assert_allclose(np.asarray(out(x, k)), r(x) @ r(k), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(dx, np.einsum("tbo,tio->bi", r(w), r(k)), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(dk, np.einsum("bi,tbo->tio", r(x), r(w)), rtol=1e-5, atol=1e-5)
    # and not the float32 products: the rounding shows at this tolerance
    assert not np.allclose(dk, np.einsum("bi,tbo->tio", x, w), rtol=1e-5, atol=1e-5)


def test_critic_layer_norm_sits_between_each_hidden_linear_map_and_its_relu():
    """With ``layer_norm`` each hidden layer is relu(LayerNorm(x W + b)), the LayerNorm starting
    at scale 1 and bias 0 (init_params as flax's init); without it the params are as before."""
    x = jax.random.normal(jax.random.key(0), (5, 7))
    critic = N.Critic((8, 8), layer_norm=True)
    params = N.init_params(critic, jax.random.key(1), x)
    mlp = params["params"]["MLP_0"]
    assert sorted(mlp) == ["LayerNorm_0", "LayerNorm_1", "TorchDense_0", "TorchDense_1",
                           "TorchDense_2"]
    assert all(np.all(mlp[f"LayerNorm_{i}"]["scale"] == 1) and
               np.all(mlp[f"LayerNorm_{i}"]["bias"] == 0) for i in range(2))
    h = x
    for i in range(2):
        h = h @ mlp[f"TorchDense_{i}"]["kernel"] + mlp[f"TorchDense_{i}"]["bias"]
        h = (h - h.mean(-1, keepdims=True)) / jnp.sqrt(h.var(-1, keepdims=True) + 1e-6)
        h = jnp.maximum(h, 0.0)
    want = (h @ mlp["TorchDense_2"]["kernel"] + mlp["TorchDense_2"]["bias"])[:, 0]
    np.testing.assert_allclose(critic.apply(params, x), want, rtol=1e-5, atol=1e-6)
    plain = N.init_params(N.Critic((8, 8)), jax.random.key(1), x)
    assert sorted(plain["params"]["MLP_0"]) == ["TorchDense_0", "TorchDense_1", "TorchDense_2"]
