"""The forward-looking reward (paper eq. 5) as a low level's reward: its settings and the
labelling of a HER batch with the agent's target critics. ``flr_dhrl`` and ``flr_pig`` put it
in place of eq. (1)'s sparse reward (:func:`flrjax.algos.low_batches.low_reward`).

Which V^l. The paper writes V^l(s, sg) = E[sum_{t=0..k} gamma^t r_alpha(s_{t+1}, sg)], the
subgoal's k steps (text under eq. 5). Three readings (``--low-value``):

- ``infinite`` (the default, the reference code's critic and the figures'): every transition
  bootstraps, with no horizon. A subgoal once reached keeps paying alpha V* for as long as the
  agent stays, so with alpha = 1 - gamma the only consistent value is -1 / (1 - gamma).
- ``reach_ends`` (:attr:`flrjax.agents.gc_td3.TD3Config.reach_ends`): the subgoal's episode
  ends where sg is reached; the reaching transition's reward alpha V(s', sg*) stands, once, for
  what comes after. A finite sum, but not bounded by k, and nothing after reaching counts.
- ``k_step`` (:attr:`flrjax.agents.gc_td3.TD3Config.horizon`, DHRL only): the paper's sum
  itself. The actor and critics see the steps left of the subgoal period k (training batches
  draw it uniformly in 1..k: the finite-horizon Bellman equation holds for every one), the TD
  target stops after the last step, and eq. 5's V of a next subgoal is read with all k steps
  left, as a fresh subgoal has them. The sum runs over k steps (t = 0..k-1), the subgoal
  period; the paper's upper limit k would make it k + 1.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax import custom_batching

from flrjax import networks, rewards
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value
from flrjax.algos.common import Run
from flrjax.options import ConfigError, Sweepable, flag, values


@dataclasses.dataclass(frozen=True)
class FLRConfig:
    """The forward-looking reward (paper eq. 5) on the low level's main critics.

    For a transition that reaches its (relabelled) subgoal, the reward is ``alpha`` times the
    best target-critic value ``V_l(s', sg')`` over ``num_candidates`` next subgoals sampled on
    the ring ``[eps, 1.25 eps]`` around the subgoal (:func:`rewards.sample_next_subgoals`,
    clipped to the subgoal box), or over the final goal with ``next_subgoal="goal"`` (the
    paper's Fig. 5 ablation). The paper: alpha 0.01 (= 1 - gamma), eps 2, delta 0.5.
    ``alpha = 0`` is plain DHRL: reaching pays eq. (1)'s 0. Inside a sweep, ``alpha``,
    ``eps`` and ``next_subgoal`` (then a bool, True for the goal) are traced per run.
    ``value_chunk``: V is evaluated only on the batch's reaching transitions, this many at a
    time (:func:`rewards.forward_looking_reward`'s ``chunk``; None: on all of them). The
    rewards are the same; the cost follows the fraction that reaches
    (``benchmarks/train_throughput.py --value-chunk`` measures it).
    """

    alpha: float = 0.01
    eps: float = 2.0
    num_candidates: int = 16
    next_subgoal: str = "sample"  # "sample" | "goal"
    value_chunk: int | None = 128
    # Matrix operands of the candidate values: "float32" (TF32 on GPUs that allow it) or
    # "bfloat16" (rounded operands, float32 accumulation; the parameters stay float32). On a
    # GPU the trainer's defaults are bfloat16 and the whole batch at once (FLR_GPU_DEFAULTS).
    value_dtype: str = "float32"
    # "xla": the candidate values as XLA computes gc_td3.value (a kernel per layer); "fused":
    # one Pallas kernel for the target actor and both target critics (gc_td3.fused_value:
    # the activations stay on chip), bfloat16 operands only; with value_chunk None it takes
    # the whole batch, reaching transitions first, and skips the others' blocks of rows
    # (skips_unreached). On a GPU the trainer's default is "fused" (fused_value.choose);
    # elsewhere the kernel runs in Pallas's interpreter.
    value_kernel: str = "xla"
    # Per run of the vmapped run axis (seeds x sweep points, in run order): is its alpha
    # positive? Under a vmap over that many runs, the candidate values are computed for those
    # runs alone (:func:`active_runs_value`): a sweep's alpha = 0 point (DHRL) pays eq. (1)'s
    # sparse reward, as alpha * max V = 0 does, without the cost. None: every run computes
    # them. Set for the runner's programs (:func:`with_runs`).
    active_runs: tuple[bool, ...] | None = None


#: The paper's FLR settings (§3.1): alpha 0.01, eps 2; 16 candidates is ours (the paper
#: samples "several").
FLR_DEFAULTS = dict(flr_alpha=0.01, flr_eps=2.0, flr_next="sample", flr_candidates=16)
#: How the trainer evaluates eq. 5's candidate values on a GPU, unless flags say otherwise:
#: the whole batch in one call (fewer, larger matrix products) with bf16 matrix operands
#: (float32 accumulation and parameters: twice the tensor cores' rate). The reward is a max
#: over randomly drawn candidates; bf16 moves it by a fraction of what a new draw of the
#: candidates does (tests/algos/test_dhrl.py, docs/benchmarks.md). Elsewhere FLRConfig's
#: own: float32, the reaching transitions only, in chunks (on a CPU the FLOPs count). With
#: bf16 the GPU computes them in one fused kernel (:func:`fused_value.choose`).
FLR_GPU_DEFAULTS = dict(flr_value_chunk=0, flr_precision="bfloat16")

GROUP = "FLR, eq. 5, default: the paper's"


@dataclasses.dataclass(frozen=True)
class FLROptions:
    """The flags of a method with the forward-looking reward; None: the paper's value
    (:data:`FLR_DEFAULTS`), or the device's (:data:`FLR_GPU_DEFAULTS`)."""

    flr_alpha: float | tuple[float, ...] | None = flag(
        None, "alpha of eq. 5 (paper 0.01; > 1 - gamma warns); comma-separated values sweep "
              "it in one vmapped run", GROUP, sweep=Sweepable("α", FLR_DEFAULTS["flr_alpha"]),
        check=(lambda v: v >= 0, ">= 0"))
    flr_eps: float | tuple[float, ...] | None = flag(
        None, "next subgoals at distance >= eps (paper 2; <= 2 delta warns); comma-separated "
              "values sweep it", GROUP, sweep=Sweepable("ε", FLR_DEFAULTS["flr_eps"]),
        check=(lambda v: v >= 0, ">= 0"))
    flr_next: str | tuple[str, ...] | None = flag(
        None, "'sample' next subgoals on the eps ring, or the final 'goal' (the paper's Fig. 5); "
              "'sample,goal' sweeps it", GROUP, type=str, choices=("sample", "goal"),
        sweep=Sweepable("next", FLR_DEFAULTS["flr_next"], traced=lambda v: v == "goal"))
    flr_candidates: int | None = flag(
        None, "next subgoals sampled per transition (default 16)", GROUP, type=int,
        check=(lambda v: v >= 1, ">= 1"))
    # It shapes the compiled step, so it is never swept; it does not change the rewards.
    flr_value_chunk: int | None = flag(
        None, "reaching transitions per V evaluation chunk (default: the whole batch on a "
              "GPU, 128 on a CPU; 0: the whole batch)", GROUP, type=int,
        check=(lambda v: v >= 0, ">= 0 (0: the whole batch)"))
    flr_precision: str | None = flag(
        None, "matrix operands of eq. 5's candidate values, float32 or bfloat16 (float32 "
              "accumulation; default: bfloat16 on a GPU, float32 on a CPU)", GROUP, type=str,
        choices=networks.PRECISIONS)


def settings(run: Run) -> dict:
    """The run's :data:`FLR_DEFAULTS` fields, with the paper's values where unset."""
    return {k: (v if getattr(run, k) is None else getattr(run, k))
            for k, v in FLR_DEFAULTS.items()}


def from_run(run: Run) -> FLRConfig:
    """The FLR settings of a run of an FLR method (its :class:`FLROptions`); the candidate
    values' kernel by :func:`fused_value.choose`."""
    d = settings(run)
    gpu = FLR_GPU_DEFAULTS if jax.default_backend() == "gpu" else {}
    chunk, precision = (gpu.get(k) if getattr(run, k) is None else getattr(run, k)
                        for k in ("flr_value_chunk", "flr_precision"))
    extra = {} if chunk is None else {"value_chunk": chunk or None}
    if precision is not None:
        extra["value_dtype"] = precision
    extra["value_kernel"] = fused_value.choose(run.value_kernel, precision or "float32",
                                               run.hidden, run.critic_layer_norm,
                                               getattr(run, "critic_atoms", 0))
    return FLRConfig(alpha=d["flr_alpha"], eps=d["flr_eps"], num_candidates=d["flr_candidates"],
                     next_subgoal=d["flr_next"], **extra)


def validate(run: Run, points: list[dict], env) -> None:
    """Eq. 5's settings at every sweep point (``rewards.validate_flr_params``: alpha and eps
    against gamma and delta, warning where the paper's guarantees no longer hold)."""
    if isinstance(run.flr_eps, tuple) and "goal" in values(run.flr_next):
        raise ConfigError("--flr-eps: a sweep over eps means nothing with --flr-next goal (the "
                          "final goal is the only candidate); list the points with --sweep")
    for point in points:
        r = run.replace(**point)
        f = settings(r)
        gamma = gc_td3.Hparams.gamma if r.gamma is None else r.gamma
        try:
            rewards.validate_flr_params(f["flr_alpha"], gamma,
                                        None if f["flr_next"] == "goal" else f["flr_eps"],
                                        env.config.delta)
        except ValueError as e:
            raise ConfigError(f"--flr-alpha / --flr-eps: {e}") from None


def resolved(flr: FLRConfig) -> dict:
    """How this run computes eq. 5's candidate values (their defaults follow the device)."""
    return dict(flr_precision=flr.value_dtype, flr_value_chunk=flr.value_chunk,
                flr_value_kernel=flr.value_kernel)


def with_runs(algo_cfg, run_points: tuple[dict, ...]):
    """``algo_cfg`` (a config with an ``flr``) with :attr:`FLRConfig.active_runs`: per run,
    is its alpha positive? Unchanged unless some run's alpha is 0 (the base method as a
    sweep's alpha = 0 point): eq. 5's candidate values are then computed for the others
    alone."""
    active = tuple(bool(p.get("flr_alpha", algo_cfg.flr.alpha) > 0) for p in run_points)
    if all(active):
        return algo_cfg
    return dataclasses.replace(algo_cfg, flr=dataclasses.replace(algo_cfg.flr,
                                                                 active_runs=active))


def candidate_value(flr: FLRConfig) -> Callable[..., jax.Array]:
    """``f(agent, obs, goals) -> [B, M]``, :func:`gc_td3.value` as ``flr`` computes it: its
    operand precision, by XLA or by the fused kernel (:attr:`FLRConfig.value_kernel`)."""
    dot_dtype = networks.dot_dtype(flr.value_dtype)
    if flr.value_kernel == "fused":
        if dot_dtype is None:
            raise ValueError("the fused candidate-value kernel computes with bfloat16 operands")
        return functools.partial(fused_value.value, dot_dtype=dot_dtype)
    return functools.partial(gc_td3.value, dot_dtype=dot_dtype)


def active_runs_value(agent: gc_td3.AgentState, active: tuple[bool, ...],
                      plain: Callable[..., jax.Array]) -> rewards.ValueFn:
    """``plain`` (a :func:`candidate_value`) of ``agent``, computed under a vmap over
    ``len(active)`` runs for the ``active`` runs alone; the others get V = 0. Their alpha is
    0, so eq. 5's reward ``alpha * max V`` is 0 whatever V is (eq. 1's reward for a reached
    subgoal). ``vmap`` alone would evaluate every run (a per-run choice runs both branches);
    this batching rule gathers the active runs' inputs, evaluates them, and scatters the
    values back. Under any other vmap, or none, it is ``plain``.

    The rule sees its inputs as one flat list of arrays: its batched flags then stay bools,
    which a pytree that converts its fields when rebuilt (brax's ``UInt64`` count in
    :attr:`gc_td3.AgentState.obs_stats`) would turn into traced arrays."""

    def evaluate(obs: jax.Array, goals: jax.Array, **wanted) -> jax.Array:
        leaves, tree = jax.tree.flatten((agent, obs, goals, wanted))

        def call(*flat):
            a, o, g, w = jax.tree.unflatten(tree, flat)
            return plain(a, o, g, **w)

        @custom_batching.custom_vmap
        def value(flat):
            return call(*flat)

        @value.def_vmap
        def _rule(axis_size, in_batched, flat):
            batched = in_batched[0]
            every = jax.vmap(call, in_axes=tuple(0 if b else None for b in batched))
            if axis_size != len(active):
                return every(*flat), True
            idx = np.flatnonzero(active)
            if not idx.size:
                shape = jax.eval_shape(every, *flat)
                return jnp.zeros(shape.shape, shape.dtype), True
            out = every(*[x[idx] if b else x for x, b in zip(flat, batched, strict=True)])
            # traced once: the others' zeros take its shape, not eval_shape's
            return jnp.zeros((axis_size, *out.shape[1:]), out.dtype).at[idx].set(out), True

        return value(leaves)

    return evaluate


def skips_unreached(flr: FLRConfig) -> bool:
    """Whether eq. 5's candidate values are computed by the fused kernel on the whole batch,
    which then skips the transitions that do not reach their subgoal (their reward does not
    read V): :func:`rewards.forward_looking_reward`'s ``reached_first``."""
    return flr.value_kernel == "fused" and flr.value_chunk is None


def next_is_goal(flr: FLRConfig) -> bool | jax.Array:
    """Whether the final goal is the next subgoal: from the name, or a sweep's traced bool."""
    return flr.next_subgoal == "goal" if isinstance(flr.next_subgoal, str) else flr.next_subgoal


def label(agent: gc_td3.AgentState, batch: dict, key: jax.Array, flr: FLRConfig, *,
          delta: float, low: jax.Array, high: jax.Array) -> rewards.FLROutput:
    """Eq. (5) on a HER batch, labelled by the agent's *target* critics and actor
    (:func:`gc_td3.value`), the networks the TD target bootstraps from, so that the reward and
    the bootstrap value of a reached subgoal are on one scale and move slowly. Candidates are
    sampled in the subgoal box ``[low, high]``. V is clipped to ``[-1 / (1 - gamma), 0]``
    (the agent's gamma) so that eq. (4)'s ``reward >= -1`` holds for ``alpha <= 1 - gamma``
    whatever the critic outputs."""
    # Both candidate sets, chosen per run: a sweep over --flr-next traces the choice.
    sampled = rewards.sample_next_subgoals(
        key, batch["goal"], eps=flr.eps, num=flr.num_candidates, low=low, high=high)
    goal_next = next_is_goal(flr)
    candidates = jnp.where(goal_next, rewards.next_subgoal_is_goal(
        batch["final_goal"], flr.num_candidates), sampled)
    plain = candidate_value(flr)
    value_fn = (functools.partial(plain, agent) if flr.active_runs is None else
                active_runs_value(agent, flr.active_runs, plain))
    return rewards.forward_looking_reward(
        value_fn, batch["next_obs"],
        batch["next_achieved_goal"], batch["goal"], candidates, alpha=flr.alpha,
        eps=jnp.where(goal_next, 0.0, flr.eps), delta=delta, v_min=-1.0 / agent.hp.one_minus_gamma,
        chunk=flr.value_chunk, reached_first=skips_unreached(flr))
