"""Low-level rewards: sparse (eq. 1), HIGL dense, and the forward-looking reward (FLR, eq. 5).

Everything here is a pure function of arrays (plus, for FLR, a value-function callable), so it
can be ``jit``-ed, ``vmap``-ed over a seed axis and called inside a ``lax.scan`` training step.
Symbols follow the paper (``flr_paper.md`` §2): ``delta`` is the success radius δ, ``alpha`` the
FLR scale α, ``eps`` the next-subgoal distance ε, ``subgoal`` the current subgoal sg_i and
``candidates`` the potential next subgoals sg'. Goals are absolute positions in goal space
(the torso's x, y in the ant mazes); a trainer that uses relative subgoals converts first.

The only host-side function is :func:`validate_flr_params`, which checks hyper-parameters once,
before training, and warns where the paper's guarantees (eqs. 4 and 6) no longer hold.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.special import ndtr
from jax.typing import ArrayLike

Array = jax.Array
ValueFn = Callable[[Array, Array], Array]
"""``value_fn(obs[B, ...], goals[B, M, g]) -> [B, M]``: the low-level value V_l(s', sg')
(also called with ``rows=n`` by :func:`forward_looking_reward`'s ``reached_first``)."""

DIST_TOL = 1e-4
"""Slack (goal-space units) in the ``‖sg' − sg‖ ≥ ε`` test of :func:`candidate_mask`.

A candidate placed at exactly distance ε (the paper's sampling, ``width=0``) comes back from
``‖(sg + ε u) − sg‖`` a float32 rounding error away from ε, i.e. below ε about half the time.
1e-4 is far above that error for goal spaces of tens of units and far below δ = 0.5.
"""


def goal_distance(a: ArrayLike, b: ArrayLike) -> Array:
    """Euclidean distance ‖a − b‖₂ over the last (goal) axis; leading axes broadcast."""
    diff = jnp.asarray(a) - jnp.asarray(b)
    return jnp.sqrt(jnp.sum(jnp.square(diff), axis=-1))


def reached_mask(achieved: ArrayLike, goal: ArrayLike, *, delta: ArrayLike = 0.5) -> Array:
    """Boolean ``‖achieved − goal‖ < delta``: the success test of eq. (1), any leading shape."""
    return goal_distance(achieved, goal) < delta


def sparse_reward(achieved: ArrayLike, goal: ArrayLike, *, delta: ArrayLike = 0.5) -> Array:
    """Eq. (1): 0 where ``‖achieved − goal‖ < delta``, −1 otherwise (floating, leading shape)."""
    dist = goal_distance(achieved, goal)
    dtype = jnp.result_type(dist.dtype, jnp.float32)
    return jnp.where(dist < delta, 0.0, -1.0).astype(dtype)


def dense_reward(achieved: ArrayLike, goal: ArrayLike, *, scale: ArrayLike = 1.0) -> Array:
    """HIGL's low-level dense reward ``−scale · ‖φ(s') − g‖₂`` (paper §3.1, HIGL baseline).

    Matches ``controller_reward`` in junsu-kim97/HIGL ``higl/utils.py``
    (``get_reward_function``): ``-np.linalg.norm(subgoal - next_ag) * scale`` for absolute
    subgoals, ``-np.linalg.norm(ag + subgoal - next_ag) * scale`` for HIGL's default relative
    subgoals (pass ``goal = ag + subgoal`` for those). ``scale`` is HIGL's ``--ctrl_rew_scale``,
    default 1.0 in its ``main.py`` and not overridden by its AntMaze scripts, so the default
    here is the unscaled distance the paper quotes.
    """
    return -jnp.asarray(scale) * goal_distance(achieved, goal)


def candidate_mask(subgoal: ArrayLike, candidates: ArrayLike, *, eps: ArrayLike) -> Array:
    """Which candidates qualify as next subgoals: ``‖sg' − subgoal‖ ≥ eps`` (up to DIST_TOL).

    ``subgoal[..., g]``, ``candidates[..., M, g]`` -> ``[..., M]`` bool. With ``eps = 0`` every
    candidate qualifies: that is the path for the "final goal as next subgoal" ablation.
    """
    subgoal = jnp.asarray(subgoal)
    dist = goal_distance(candidates, subgoal[..., None, :])
    return dist >= jnp.asarray(eps) - DIST_TOL


class FLROutput(NamedTuple):
    """Per-transition results of :func:`forward_looking_reward` (all ``[B]``)."""

    reward: Array
    """eq. (5) reward."""
    reached: Array
    """bool, ``‖next_achieved − subgoal‖ < delta`` (for the Fig. 4b gap)."""
    num_qualified: Array
    """int32, candidates with ``‖sg' − subgoal‖ ≥ eps`` (0 -> fallback)."""
    best_value: Array
    """max over qualifying candidates of V_l(s', sg') (−inf if none)."""


def forward_looking_reward(
    value_fn: ValueFn,
    next_obs: ArrayLike,
    next_achieved: ArrayLike,
    subgoal: ArrayLike,
    candidates: ArrayLike,
    *,
    alpha: ArrayLike,
    eps: ArrayLike,
    delta: ArrayLike = 0.5,
    no_candidate_reward: ArrayLike = 0.0,
    v_min: ArrayLike | None = None,
    chunk: int | None = None,
    reached_first: bool = False,
) -> FLROutput:
    """Forward-looking reward, eq. (5), with the reached mask and diagnostics.

    For each transition b::

        reward[b] = alpha * max_{m: ‖cand[b,m] − subgoal[b]‖ ≥ eps} V_l(next_obs[b], cand[b,m])
                        if ‖next_achieved[b] − subgoal[b]‖ < delta
                    -1  otherwise

    Args:
      value_fn: ``value_fn(next_obs[B, ...], candidates[B, M, g]) -> [B, M]``, the low-level
        value V_l(s', sg') (use the target critic; the reward is a label, so it is wrapped in
        ``stop_gradient``).
      next_obs: ``[B, ...]`` next observations s'.
      next_achieved: ``[B, g]`` achieved goals φ(s').
      subgoal: ``[B, g]`` the (HER-relabelled) subgoal sg_i of each transition.
      candidates: ``[B, M, g]`` potential next subgoals sg', e.g. from
        :func:`sample_next_subgoals`, or :func:`next_subgoal_is_goal` with ``eps=0``.
      alpha: α ≥ 0 (0 gives eq. (1)); eq. (4) wants α ≤ 1 − γ (:func:`validate_flr_params`).
      eps: ε; only candidates at distance ≥ ε from ``subgoal`` count (up to ``DIST_TOL``).
        ``eps=0`` counts every candidate (the final-goal ablation).
      delta: δ, the success radius of eq. (1).
      no_candidate_reward: reward for a transition that reaches ``subgoal`` but has no
        qualifying candidate (e.g. all were clipped to within ε by goal-space bounds). Default
        0, the sparse reward of eq. (1): with nothing to look forward to, FLR falls back to the
        reward it extends (FLR with α = 0). The paper never meets this case (it samples at
        distance ε, so every candidate qualifies); −1 would punish reaching the subgoal, and
        any value of V would be invented. ``num_qualified`` lets the trainer log how often it
        happens.
      v_min: if given (e.g. ``-1 / (1 - gamma)``), V is clipped to ``[v_min, 0]`` first, so the
        eq. (4) bound ``reward ≥ −1`` holds even when a learned critic overshoots.
      chunk: if given (and below B), V is evaluated only for the transitions that reach their
        subgoal, the only ones whose reward reads it: they are gathered ``chunk`` at a time in
        a ``lax.while_loop`` that runs ceil(reached / chunk) times. The rewards are those of
        the full evaluation; ``best_value`` of the other transitions is then −inf. The
        evaluation (M critic and actor passes per transition) is the FLR's whole cost, so it
        shrinks with the fraction of reaching transitions.
      reached_first: instead of ``chunk``, V is evaluated once on the whole batch reordered
        so that the reaching transitions come first, with their count:
        ``value_fn(next_obs, candidates, rows=n)``, whose values past the first ``n`` rows are
        not read. For a value function that skips those rows' work (the fused kernel,
        :func:`flrjax.agents.gc_td3.fused_value.value`) the cost follows the fraction of
        reaching transitions without a loop. The rewards are those of the full evaluation;
        ``best_value`` of the other transitions is −inf.

    Returns:
      :class:`FLROutput` of ``[B]`` arrays: reward, reached, num_qualified, best_value.

    All arguments may be traced (``alpha``/``eps``/``delta`` can be vmapped for sweeps); only
    ``value_fn`` is a Python callable and ``v_min`` is ``None`` or a number/array.
    """
    next_achieved = jnp.asarray(next_achieved)
    subgoal = jnp.asarray(subgoal)
    candidates = jnp.asarray(candidates)
    if candidates.ndim != 3 or subgoal.ndim != 2 or next_achieved.ndim != 2:
        raise ValueError(
            "expected next_achieved[B, g], subgoal[B, g], candidates[B, M, g]; got "
            f"{next_achieved.shape}, {subgoal.shape}, {candidates.shape}"
        )
    batch, num = candidates.shape[:2]
    next_obs = jnp.asarray(next_obs)
    qualified = candidate_mask(subgoal, candidates, eps=eps)
    num_qualified = jnp.sum(qualified, axis=-1, dtype=jnp.int32)
    reached = reached_mask(next_achieved, subgoal, delta=delta)

    def best(order: Array | None, **wanted: Array) -> Array:
        """max over the qualifying candidates of V (clipped) for the transitions ``order`` (all
        of them for None); ``wanted`` goes to ``value_fn``."""
        pick = (lambda x: x) if order is None else (lambda x: x[order])
        values = jax.lax.stop_gradient(value_fn(pick(next_obs), pick(candidates), **wanted))
        want = (batch if order is None else order.shape[0], num)
        if values.shape != want:
            raise ValueError(f"value_fn must return [B, M] = {want}, got {values.shape}")
        if v_min is not None:
            values = jnp.clip(values, v_min, 0.0)
        return jnp.max(jnp.where(pick(qualified), values, -jnp.inf), axis=-1)

    with jax.named_scope("flr_values"):  # the step profile's group for eq. 5's evaluations
        if reached_first:
            order = jnp.argsort(~reached, stable=True)
            in_order = best(order, rows=jnp.sum(reached, dtype=jnp.int32))
            best_value = jnp.where(reached, jnp.empty_like(in_order).at[order].set(in_order),
                                   -jnp.inf)
        elif chunk is None or chunk >= batch:
            best_value = best(None)
        else:
            best_value = _best_of_reached(best, reached, chunk)

    # Select with `where` rather than multiply so that -inf (no candidate) never leaks through.
    look_ahead = jnp.where(num_qualified > 0, jnp.asarray(alpha) * best_value, no_candidate_reward)
    reward = jnp.where(reached, look_ahead, -1.0).astype(best_value.dtype)
    return FLROutput(reward, reached, num_qualified, best_value)


def _best_of_reached(best: Callable[[Array | None], Array], reached: Array, chunk: int
                     ) -> Array:
    """``best(rows)`` of the reaching transitions, ``chunk`` rows per iteration of a while loop
    that stops once they are done (−inf elsewhere). Under ``vmap`` (seeds) it runs until every
    seed's are done."""
    batch = reached.shape[0]
    padded = -(-batch // chunk) * chunk
    # reaching rows first, in batch order; the padding index `batch` is dropped on scatter
    order = jnp.concatenate([jnp.argsort(~reached, stable=True),
                             jnp.full(padded - batch, batch, jnp.int32)])
    n = jnp.sum(reached)

    def body(carry: tuple[Array, Array]) -> tuple[Array, Array]:
        i, out = carry
        rows = jax.lax.dynamic_slice(order, (i * chunk,), (chunk,))
        safe = jnp.minimum(rows, batch - 1)  # a chunk may run past the reaching ones
        value = jnp.where(reached[safe], best(safe), -jnp.inf)
        return i + 1, out.at[rows].set(value, mode="drop")

    dtype = jax.eval_shape(best, order[:chunk]).dtype
    init = (jnp.zeros((), jnp.int32), jnp.full(batch, -jnp.inf, dtype))
    return jax.lax.while_loop(lambda c: c[0] * chunk < n, body, init)[1]


def sample_next_subgoals(
    key: Array,
    subgoal: ArrayLike,
    *,
    eps: ArrayLike,
    num: int,
    width: ArrayLike | None = None,
    low: ArrayLike | None = None,
    high: ArrayLike | None = None,
) -> Array:
    """Sample ``num`` candidate next subgoals per subgoal on the ring ``eps ≤ r ≤ eps + width``.

    ``subgoal[..., g]`` -> ``[..., num, g]``. The paper samples "at a distance of ε" (§2.3);
    since V_l(s', sg') falls with the distance of sg' from s' (itself within δ of sg), the max
    in eq. (5) over ``‖sg' − sg‖ ≥ ε`` sits near that inner circle, so a thin ring estimates it.

    * Direction: uniform on the unit sphere of the g-dim goal space (normalised Gaussian).
    * Radius: uniform in *area* (volume) of the ring, ``r = (ε^g + u((ε+w)^g − ε^g))^(1/g)``,
      so points are uniform over the ring: an unbiased Monte-Carlo cover of the set the max
      runs over (uniform-in-radius would crowd the inner rim).
    * ``width`` defaults to ``0.25 * eps`` (0.5 = δ at the paper's ε = 2): close to the paper's
      circle, yet with some radial spread so that clipping or a wall at exactly ε does not
      leave every candidate in the same place. ``width=0`` is exactly the paper's circle.
    * ``low``/``high`` (broadcastable to ``[g]``): candidates are clipped into the goal space.
      Clipping can pull a candidate closer than ε; it is returned anyway (shapes are static)
      and :func:`forward_looking_reward` masks it out by distance, and falls back to
      ``no_candidate_reward`` if none is left.

    Deterministic for a given key; ``eps``/``width`` may be traced, ``num`` is static.
    """
    subgoal = jnp.asarray(subgoal)
    dim = subgoal.shape[-1]
    dtype = jnp.result_type(subgoal.dtype, jnp.float32)
    eps = jnp.asarray(eps, dtype)
    width = 0.25 * eps if width is None else jnp.asarray(width, dtype)
    # One Gaussian draw for both parts (each RNG call is a separate threefry kernel to
    # compile and run): g entries give the direction, the last one, through the normal CDF,
    # a Uniform(0, 1) for the radius.
    z = jax.random.normal(key, subgoal.shape[:-1] + (num, dim + 1), dtype)
    direction = z[..., :dim]
    norm = jnp.linalg.norm(direction, axis=-1, keepdims=True)
    direction = direction / jnp.maximum(norm, jnp.finfo(dtype).tiny)

    u = ndtr(z[..., dim:])
    inner, outer = eps**dim, (eps + width) ** dim
    radius = (inner + u * (outer - inner)) ** (1.0 / dim)
    # Keep r inside [eps, eps + width] despite rounding in the power / root.
    radius = jnp.clip(radius, eps, eps + width)

    candidates = subgoal[..., None, :] + radius * direction
    if low is not None or high is not None:
        candidates = jnp.clip(candidates, low, high)
    return candidates


def next_subgoal_is_goal(goal: ArrayLike, num: int = 1) -> Array:
    """Candidates for the ablation "final goal as the next subgoal" (``--flr-next goal``).

    ``goal[..., g]`` -> ``[..., num, g]`` (the episode's final goal, broadcast). Call the FLR
    with ``eps=0`` so the distance mask keeps it even when it lies within ε of the subgoal.
    ``num > 1`` only matches the shape of sampled candidates; the copies are identical.
    """
    goal = jnp.asarray(goal)
    return jnp.broadcast_to(goal[..., None, :], goal.shape[:-1] + (num, goal.shape[-1]))


def validate_flr_params(
    alpha: float, gamma: float, eps: float | None = None, delta: float | None = None
) -> None:
    """Check FLR hyper-parameters once, on the host, before training.

    Raises ``ValueError`` for ``alpha < 0``, ``gamma`` outside (0, 1), ``eps < 0`` or
    ``delta ≤ 0``. Warns (``UserWarning``) when ``alpha > 1 − gamma``: eq. (4) then no
    longer guarantees ``reward ≥ −1``, so reaching a subgoal can pay less than missing it.
    Warns when ``eps ≤ 2·delta`` (given both): eq. (6) then no longer ensures the chosen next
    subgoal is unreached at s'; only a warning because the paper's own ablation runs
    ε = δ = 0.5. Pass ``eps=None`` for the final-goal ablation. ``alpha = 0`` is allowed:
    eq. (5) then pays exactly eq. (1)'s 0 for reaching, so an FLR trainer with α = 0 is its
    sparse-reward baseline (the baseline point of a vmapped sweep).
    """
    if not alpha >= 0:
        raise ValueError(f"FLR needs alpha >= 0, got {alpha}")
    if not 0 < gamma < 1:
        raise ValueError(f"gamma must be in (0, 1), got {gamma}")
    # Small slack: 1 - 0.9 == 0.09999999999999998 must not flag alpha = 0.1.
    if alpha > (1.0 - gamma) + 1e-12:
        warnings.warn(
            f"alpha={alpha} > 1 - gamma={1.0 - gamma:.6g}: eq. (4) no longer guarantees "
            "reward >= -1, so the FLR can discourage reaching subgoals",
            UserWarning,
            stacklevel=2,
        )
    if delta is not None and not delta > 0:
        raise ValueError(f"delta must be > 0, got {delta}")
    if eps is not None:
        if eps < 0:
            raise ValueError(f"eps must be >= 0, got {eps}")
        if delta is not None and eps <= 2 * delta:
            warnings.warn(
                f"eps={eps} <= 2*delta={2 * delta}: eq. (6) no longer ensures the best next "
                "subgoal is not already reached at s'",
                UserWarning,
                stacklevel=2,
            )
