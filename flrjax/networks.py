"""Flax (linen) networks of the goal-conditioned agents.

Reference: jayLEE0301/dhrl_official (``core.py`` = ``DHRL/rl/agent/core.py``, ``main.py`` =
``DHRL/main.py``). DHRL builds its MLPs with
``rl/utils/net_utils.mlp`` (as in LunjunZhang/world-model-as-a-graph, whose ``rl`` package DHRL
derives from): ``nn.Linear`` layers with ReLU between them, PyTorch's default initialisation.

* :class:`Actor` -- ``core.py Actor``: 3x256 ReLU trunk, a linear head, ``tanh(.) * scale +
  offset``. The low level uses ``scale = action_max, offset = 0``; DHRL's high level uses the
  same network with ``scale = subgoal_scale, offset = subgoal_offset``.
* :class:`Critic` -- ``core.py Critic``: 3x256 ReLU MLP to one scalar. The caller concatenates
  its input (obs, goal, scaled action); what the scalar means (a distance or a Q value) is the
  agent's business (``agents/gc_td3/networks.py``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp

Array = jax.Array
Params = Any

HIDDEN_SIZES = (256, 256, 256)  # main.py --hid_size 256, --n_hids 3 (--activ relu)
#: Matrix-operand precisions of a pass (:attr:`TorchDense.dot_dtype` by name).
PRECISIONS = ("float32", "bfloat16")


def dot_dtype(precision: str) -> Any:
    """:attr:`TorchDense.dot_dtype` of a :data:`PRECISIONS` name (None: float32 as is)."""
    return None if precision == "float32" else jnp.dtype(precision)


@functools.partial(jax.custom_vjp, nondiff_argnums=(2,))
def low_precision_dot(x: Array, kernel: Array, dtype: Any) -> Array:
    """``x @ kernel`` with both operands rounded to ``dtype``, accumulated and returned in
    float32; its gradients are ``dtype`` products too.

    JAX's own transpose of ``dot(x.astype(bf16), k.astype(bf16), preferred_element_type=f32)``
    multiplies the float32 cotangent with the bf16 operand, which XLA promotes to a float32
    product (TF32 on the GPU, not the bf16 rate), and rounds the weight gradient to bf16 on
    its way back through the cast. Here both gradient products take the cotangent rounded to
    ``dtype`` and the saved rounded operands, and return float32: the backward runs at the
    forward's rate and the gradients reach Adam unrounded. bf16 has float32's exponent range,
    so the cotangent needs no loss scaling.
    """
    return _dot(x.astype(dtype), kernel.astype(dtype))


def _dot(a: Array, b: Array) -> Array:
    return jnp.dot(a, b, preferred_element_type=jnp.float32)


def _low_precision_dot_fwd(x: Array, kernel: Array, dtype: Any) -> tuple[Array, tuple]:
    x, kernel = x.astype(dtype), kernel.astype(dtype)
    return _dot(x, kernel), (x, kernel)


def _low_precision_dot_bwd(dtype: Any, res: tuple, g: Array) -> tuple[Array, Array]:
    x, kernel = res
    g = g.astype(dtype)
    dx = _dot(g, kernel.T)  # [..., in]
    # [in, out], as (g^T x)^T: XLA's CPU backend has no bf16 kernel for x^T g once vmap
    # batches g and not x (the twin critics' shared input)
    dk = _dot(g.reshape(-1, g.shape[-1]).T, x.reshape(-1, x.shape[-1])).T
    return dx, dk


low_precision_dot.defvjp(_low_precision_dot_fwd, _low_precision_dot_bwd)


def _uniform_init(bound: float):
    """``U(-bound, bound)`` initialiser (any shape)."""

    def init(key: Array, shape: Sequence[int], dtype=jnp.float32) -> Array:
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    return init


class TorchDense(nn.Module):
    """Linear layer initialised like ``torch.nn.Linear``: weight and bias ``U(±1/sqrt(fan_in))``.

    Keeps the reference's initial critic/actor outputs (and so its early learning dynamics);
    flax's default (LeCun normal kernel, zero bias) would differ.
    """

    features: int
    # Operand dtype of the matrix product (None: the inputs' float32). With bfloat16 the
    # operands are rounded to it and the product accumulates and returns in float32: the
    # tensor cores' bf16 rate, with the parameters kept in float32. Its gradients are bf16
    # products too (:func:`low_precision_dot`), for the training passes (TD3Config's
    # train_precision).
    dot_dtype: Any = None

    @nn.compact
    def __call__(self, x: Array) -> Array:
        fan_in = x.shape[-1]
        bound = float(fan_in) ** -0.5
        kernel = self.param("kernel", _uniform_init(bound), (fan_in, self.features))
        bias = self.param("bias", _uniform_init(bound), (self.features,))
        if self.dot_dtype is None:
            return jnp.dot(x, kernel) + bias
        return low_precision_dot(x, kernel, self.dot_dtype) + bias


class MLP(nn.Module):
    """``hidden_sizes`` ReLU layers then a linear layer of ``out_size`` (net_utils.mlp); with
    ``layer_norm``, a LayerNorm between each hidden layer's linear map and its ReLU (not the
    reference's: an opt-in lever of the critics, as FastTD3's)."""

    hidden_sizes: Sequence[int]
    out_size: int
    dot_dtype: Any = None  # TorchDense.dot_dtype
    layer_norm: bool = False

    @nn.compact
    def __call__(self, x: Array) -> Array:
        for size in self.hidden_sizes:
            x = TorchDense(size, self.dot_dtype)(x)
            x = nn.relu(nn.LayerNorm()(x) if self.layer_norm else x)
        return TorchDense(self.out_size, self.dot_dtype)(x)


class Actor(nn.Module):
    """Deterministic policy ``tanh(MLP(x)) * scale + offset`` (core.py ``Actor.forward``)."""

    action_size: int
    hidden_sizes: Sequence[int] = HIDDEN_SIZES
    scale: float | Sequence[float] = 1.0
    offset: float | Sequence[float] = 0.0
    dot_dtype: Any = None  # TorchDense.dot_dtype

    @nn.compact
    def __call__(self, x: Array) -> Array:
        mean = MLP(self.hidden_sizes, self.action_size, self.dot_dtype)(x)
        return jnp.tanh(mean) * jnp.asarray(self.scale) + jnp.asarray(self.offset)


class Critic(nn.Module):
    """Scalar head over a concatenated (obs, goal, scaled action) input (core.py ``Critic``),
    with :attr:`MLP.layer_norm` where asked; with ``atoms``, ``atoms`` logits of a categorical
    value (not the reference's) in place of the scalar."""

    hidden_sizes: Sequence[int] = HIDDEN_SIZES
    dot_dtype: Any = None  # TorchDense.dot_dtype
    layer_norm: bool = False
    atoms: int = 0

    @nn.compact
    def __call__(self, x: Array) -> Array:
        out = MLP(self.hidden_sizes, max(self.atoms, 1), self.dot_dtype, self.layer_norm)(x)
        return out if self.atoms else out[..., 0]


def init_params(module: nn.Module, key: Array, *inputs: Array) -> Params:
    """``module.init(key, *inputs)`` for a module built of :class:`TorchDense` layers, with every
    parameter taken from ONE uniform draw (scaled per layer to ``U(±1/sqrt(fan_in))``); a
    LayerNorm starts as flax's does (scale 1, bias 0).

    Same distribution as ``module.init``, different numbers. One random call instead of one per
    parameter: each threefry call adds its own XLA compile time.
    """
    shapes = jax.eval_shape(module.init, key, *inputs)
    total = sum(math.prod(leaf.shape) for leaf in jax.tree.leaves(shapes))
    u = jax.random.uniform(key, (total,), jnp.float32, -1.0, 1.0)
    offset = 0

    def take(shape: tuple[int, ...], bound: float) -> Array:
        nonlocal offset
        n = math.prod(shape)
        out = u[offset:offset + n].reshape(shape) * bound
        offset += n
        return out

    def fill(tree: Mapping[str, Any]) -> dict[str, Any]:
        if "kernel" in tree:  # a TorchDense layer
            bound = float(tree["kernel"].shape[0]) ** -0.5
            return {name: take(leaf.shape, bound) for name, leaf in tree.items()}
        if "scale" in tree:  # a LayerNorm
            return {"scale": jnp.ones(tree["scale"].shape), "bias": jnp.zeros(tree["bias"].shape)}
        return {name: fill(sub) for name, sub in tree.items()}

    return fill(shapes)
