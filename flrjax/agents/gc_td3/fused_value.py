"""An actor and a twin critic on many rows in one fused GPU kernel (Pallas, Triton backend):
eq. 5's candidate values and DHRL's subgoal testing.

:func:`acting.value` on ``B x M`` candidate rows is a target actor and two target critics, 12
matrix products of ``B M`` rows by 256. As separate XLA kernels each product writes its
``B M x 256`` activations to GPU memory and the next reads them back: at 5 seeds x 1024 x 16
candidates that is ~40 MB per layer, and memory, not the tensor cores, sets the pace. Here a
block of rows goes through all three networks inside one kernel: the activations stay on chip
and only the inputs (``[obs, goal]`` rows) and the two raw critic outputs touch memory
(docs/benchmarks.md compares it with XLA's kernels). Subgoal testing's landmark-to-subgoal distances
(:func:`acting.distance`: the online actor and the distance critics) are the same products.

The arithmetic is that of :func:`acting.value` / :func:`acting.distance` with bf16 matrix
operands (``dot_dtype=bfloat16``): float32 accumulation, biases and activations rounded to
bf16 only as the next product's operand. The summation order differs: the critics' first
layer is ``[obs, goal] W_x + u W_u`` instead of one product over the concatenated input, and
products are split into column chunks (``chunk_cols``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
from jax.experimental import pallas as pl
from jax.sharding import PartitionSpec as P

from flrjax.agents.gc_td3.networks import (
    actor_input,
    distance_from_output,
    goal_input,
    q_from_output,
    state_input,
)
from flrjax.agents.gc_td3.state import AgentState

Array = jax.Array

#: Rows per kernel instance and its Triton settings (num_warps, num_stages): the fastest of
#: the settings timed on a GPU (docs/benchmarks.md).
BLOCK_ROWS = 128
NUM_WARPS = 8
NUM_STAGES = 1
#: Width of the column chunks each product is split into (256: whole layers).
CHUNK_COLS = 128


def _pad_to(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


def _pow2(n: int) -> int:
    """Smallest power of two >= max(n, 16) (Triton's block and dot sizes)."""
    return max(16, 1 << (n - 1).bit_length())


#: How the bf16 actor-and-twin-critic evaluations are computed: XLA's kernels, or this one.
KERNELS = ("xla", "fused")


def choose(kernel: str | None, precision: str, hidden: int, layer_norm: bool = False,
           atoms: int = 0) -> str:
    """``kernel`` if given, else ``"fused"`` where it applies (GPUs, bfloat16 operands,
    :func:`supported` widths, scalar critics without LayerNorm) and ``"xla"`` elsewhere."""
    if kernel is not None:
        return kernel
    fits = precision == "bfloat16" and supported(hidden) and not layer_norm and not atoms
    return "fused" if jax.default_backend() == "gpu" and fits else "xla"


def supported(hidden: int) -> bool:
    """Whether the kernel takes hidden layers this wide: a power of two >= 16 (Triton's tiles)."""
    return hidden >= 16 and hidden & (hidden - 1) == 0


def _layers(params: Any) -> list[tuple[Array, Array]]:
    """``(kernel, bias)`` of each TorchDense layer of an MLP's params, in order."""
    mlp = params["params"]["MLP_0"]
    return [(mlp[f"TorchDense_{i}"]["kernel"], mlp[f"TorchDense_{i}"]["bias"])
            for i in range(len(mlp))]


def _dense(parts: list[tuple[Array, Any, int]], b_ref: Any, cols: int) -> list[Array]:
    """``sum_p h_p W_p + b`` in float32, as column chunks of width ``cols``: ``parts`` are
    ``(h, w_ref, row)``, an input chunk and the rows ``row:row + width`` of its weights."""
    n = b_ref.shape[1]
    c = min(cols, n)
    out = []
    for j in range(0, n, c):
        acc = b_ref[:, j:j + c]
        for h, w_ref, r in parts:
            acc = acc + jnp.dot(h, w_ref[r:r + h.shape[1], j:j + c],
                                preferred_element_type=jnp.float32)
        out.append(acc)
    return out


def _rows_of(hs: list[Array], w_ref: Any) -> list[tuple[Array, Any, int]]:
    """Input chunks ``hs`` with the rows of ``w_ref`` each multiplies."""
    starts = [sum(h.shape[1] for h in hs[:i]) for i in range(len(hs))]
    return [(h, w_ref, r) for h, r in zip(hs, starts, strict=True)]


def _kernel(live_ref, xa_ref, xc_ref, *refs, n_hidden: int, dtype: Any, cols: int):
    """One block of rows: the actor, then both critics of the twin; writes their raw outputs,
    or zeros where ``live_ref`` says none of the block's rows is wanted. Activations are lists
    of column chunks (``cols`` wide), rounded to ``dtype`` as the next product's operands."""
    q_refs = refs[-2:]
    live = live_ref[0] > 0

    @pl.when(jnp.logical_not(live))
    def _():
        for q_ref in q_refs:
            q_ref[...] = jnp.zeros(q_ref.shape, q_ref.dtype)

    @pl.when(live)
    def _():
        _block(xa_ref, xc_ref, refs, n_hidden, dtype, cols)


def _block(xa_ref, xc_ref, refs, n_hidden: int, dtype: Any, cols: int) -> None:
    """:func:`_kernel`'s networks on one block of rows."""
    it = iter(refs[:-2])
    q_refs = refs[-2:]

    def relu(chunks):
        return [jnp.maximum(a, 0.0).astype(dtype) for a in chunks]

    hs = [xa_ref[...]]
    for _ in range(n_hidden):
        w = next(it)
        hs = relu(_dense(_rows_of(hs, w), next(it), cols))
    w = next(it)
    # the action tanh(m) * action_max + action_offset enters the critics as the unit action
    # (a - action_offset) / action_max (networks.critic_input): tanh(m)
    u = [jnp.tanh(m).astype(dtype) for m in _dense(_rows_of(hs, w), next(it), cols)]
    xc = xc_ref[...]
    for q_ref in q_refs:
        w_x, w_u = next(it), next(it)
        hs = relu(_dense([(xc, w_x, 0), *_rows_of(u, w_u)], next(it), cols))
        for _ in range(n_hidden - 1):
            w = next(it)
            hs = relu(_dense(_rows_of(hs, w), next(it), cols))
        w_out, b_out = next(it), next(it)
        q = b_out[0, 0]
        for h, _, r in _rows_of(hs, w_out):
            q = q + jnp.sum(h.astype(jnp.float32) * w_out[:, r:r + h.shape[1]], axis=1)
        q_ref[...] = q


def _operands(actor_params: Any, twin_params: Any, dtype: Any, k_pad: int, a_pad: int
              ) -> list[Array]:
    """The kernel's weight operands, padded with zeros to Triton's sizes, in kernel order
    (zero rows and columns add nothing; the padded actions are tanh(0) = 0)."""
    actor = _layers(actor_params)
    critic = _layers(twin_params)  # leading twin axis
    a = actor[-1][0].shape[1]

    def pad(x, rows, cols):
        return jnp.pad(x, ((0, rows - x.shape[0]), (0, cols - x.shape[1])))

    def row(v, cols):
        return pad(v.reshape(1, -1).astype(jnp.float32), 1, cols)

    ops = []
    for i, (w, b) in enumerate(actor):
        out = a_pad if i == len(actor) - 1 else w.shape[1]
        ops += [pad(w, k_pad if i == 0 else w.shape[0], out).astype(dtype), row(b, out)]
    obs_goal = critic[0][0].shape[1] - a
    for t in range(2):
        w0, b0 = critic[0][0][t], critic[0][1][t]
        ops += [pad(w0[:obs_goal], k_pad, w0.shape[1]).astype(dtype),
                pad(w0[obs_goal:], a_pad, w0.shape[1]).astype(dtype), row(b0, w0.shape[1])]
        for w, b in critic[1:-1]:
            ops += [w[t].astype(dtype), row(b[t], w.shape[2])]
        w_out, b_out = critic[-1]
        ops += [w_out[t].reshape(1, -1).astype(jnp.float32), b_out[t].reshape(1, 1)]
    return ops


def _per_device(kernel):
    """``kernel`` as each device's own call on its own runs' rows where the program is split
    over several devices (traced under the run axis's mesh, :func:`run_axis.vmap_runs`),
    else ``kernel``. XLA partitions the rest of a split program, but cannot split a Pallas
    kernel along the runs: left to it, every device would compute every run's rows. The
    vmap over the runs names the mesh axis, so it shards the runs of this ``shard_map``."""
    mesh = jax.sharding.get_abstract_mesh()
    if mesh.empty or mesh.size == 1:
        return kernel
    return jax.shard_map(kernel, in_specs=P(), out_specs=P(), check_vma=False)


@dataclasses.dataclass(frozen=True)
class KernelSettings:
    """Rows per kernel instance, Triton's ``num_warps`` and ``num_stages``, products split
    into ``chunk_cols``-wide column chunks. The defaults are the fastest of those
    timed (docs/benchmarks.md)."""

    block_rows: int = BLOCK_ROWS
    num_warps: int = NUM_WARPS
    num_stages: int = NUM_STAGES
    chunk_cols: int = CHUNK_COLS


def twin_outputs(state: AgentState, actor_params: Any, twin_params: Any, obs: Array,
                 goal: Array, dot_dtype: Any = jnp.bfloat16,
                 settings: KernelSettings = KernelSettings(), wanted: Array | None = None
                 ) -> Array:
    """Raw outputs ``[2, ...]`` of the twin critic ``twin_params`` at ``a = pi(s, g)`` of the
    actor ``actor_params`` (:func:`networks.critic_outputs` of :func:`networks.policy`), for
    ``obs[..., o]`` and ``goal[..., g]`` of one shape, in one kernel: Triton's on a GPU,
    Pallas's interpreter elsewhere (the tests'). ``wanted`` (traced): only the first
    ``wanted`` rows of the flattened leading axes are; blocks of rows past them skip their
    products and give 0 (None: all). An agent with a horizon sees a fresh goal (all its steps
    left), as :func:`acting.value` and :func:`acting.distance` read it; with
    :attr:`TD3Config.obs_norm` the inputs normalised as the networks see them."""
    cfg, stats = state.config, state.obs_stats
    interpret = jax.default_backend() != "gpu"
    s = state_input(cfg, obs, stats=stats)  # the observation as the networks see it
    lead, width = obs.shape[:-1], s.shape[-1] + goal.shape[-1]
    a = _layers(actor_params)[-1][0].shape[1]
    k_pad, a_pad = _pow2(width), _pow2(a)
    rows = math.prod(lead)
    block = settings.block_rows
    rows_pad = _pad_to(rows, block)

    def rows_of(x):
        x = x.reshape(rows, width)
        return jnp.pad(x, ((0, rows_pad - rows), (0, k_pad - width))).astype(dot_dtype)

    xa = rows_of(actor_input(cfg, obs, goal, stats=stats))
    xc = rows_of(jnp.concatenate([s, goal_input(obs, goal, False, stats)], axis=-1))
    ops = _operands(actor_params, twin_params, dot_dtype, k_pad, a_pad)
    starts = jnp.arange(0, rows_pad, block)  # each block's first row
    live = jnp.ones_like(starts) if wanted is None else (starts < wanted).astype(jnp.int32)
    live_spec = pl.BlockSpec((1,), lambda i: (i,))
    row_spec = pl.BlockSpec((block, k_pad), lambda i: (i, 0))
    whole = [pl.BlockSpec(x.shape, lambda i: (0, 0)) for x in ops]
    out_spec = pl.BlockSpec((block,), lambda i: (i,))
    kwargs = {}
    if not interpret:
        from jax.experimental.pallas import triton as plt
        kwargs["compiler_params"] = plt.CompilerParams(num_warps=settings.num_warps,
                                                       num_stages=settings.num_stages)
    q = _per_device(pl.pallas_call(
        functools.partial(_kernel, n_hidden=len(cfg.hidden_sizes), dtype=dot_dtype,
                          cols=settings.chunk_cols),
        out_shape=[jax.ShapeDtypeStruct((rows_pad,), jnp.float32)] * 2,
        grid=(rows_pad // block,),
        in_specs=[live_spec, row_spec, row_spec, *whole],
        out_specs=[out_spec, out_spec],
        interpret=interpret,
        name="actor_twin_critic",
        **kwargs,
    ))(live, xa, xc, *ops)
    return jnp.stack(q)[:, :rows].reshape(2, *lead)


def value(state: AgentState, obs: Array, goals: Array, *, dot_dtype: Any = jnp.bfloat16,
          settings: KernelSettings = KernelSettings(), rows: Array | None = None) -> Array:
    """:func:`acting.value` (``obs[B, o]``, ``goals[B, M, g]`` -> ``[B, M]``: the target actor
    and target critics) in one kernel. ``rows``: only ``obs[:rows]``'s values are wanted (the
    others' blocks of rows are skipped; their values are then meaningless)."""
    if state.config.critic_atoms:
        raise ValueError("the fused kernel reads scalar critics, not critic_atoms' logits")
    obs_b = jnp.broadcast_to(obs[..., None, :], goals.shape[:-1] + obs.shape[-1:])
    wanted = None if rows is None else rows * goals.shape[-2]
    out = twin_outputs(state, state.actor.target_params, state.critic.target_params, obs_b,
                       goals, dot_dtype, settings, wanted)
    return jnp.min(q_from_output(out, state.config, state.hp), axis=0)


def distance(state: AgentState, obs: Array, goal: Array, dot_dtype: Any = jnp.bfloat16,
             settings: KernelSettings = KernelSettings()) -> Array:
    """:func:`acting.distance` (``obs[..., o]``, ``goal[..., g]`` -> ``[...]``: the online actor
    and distance critics) in one kernel."""
    out = twin_outputs(state, state.actor.params, state.critic_g.params, obs, goal, dot_dtype,
                       settings)
    return jnp.maximum(jnp.min(distance_from_output(out, state.config, state.hp), axis=0), 0.0)
