"""HER replay buffer: pure functions over a pytree of preallocated, fixed-size arrays.

The buffer is a ring of whole episodes of one fixed length ``T`` (the trainer runs ``E`` envs in
lockstep and every episode lasts exactly ``T`` steps). All functions are jit-able and
vmap-able (over a leading seed axis): shapes are static, there are no Python loops over data,
and the buffer knows nothing of rewards -- the caller computes them after relabelling.

Fields (the caller chooses them at :func:`init`, by name) are of two kinds:

* **per-state** fields, stored ``[capacity, T + 1, ...]``: one entry per visited state, index
  ``t`` is the state *before* action ``t`` and index ``T`` the final state. Put here what
  describes a state: ``obs``, ``achieved_goal`` (required by HER), extras such as ``torso_z``.
  A sampled transition gets both ``x`` (index ``t``) and ``next_x`` (index ``t + 1``).
* **per-transition** fields, stored ``[capacity, T, ...]``: one entry per step ``t``. Put here
  what is decided at a step: ``action``, ``goal`` (the goal the policy was conditioned on at
  step ``t``; HER relabels it), extras such as the high-level subgoal.

Writing, one step at a time (inside the trainer's scan)::

    state = insert_step(state, t, step)      # step: every field, leading axis E, time index t
    state = insert_final(state, last)        # per-state fields of the final state (index T)
    state = finish_episodes(state)           # the E episodes become sampleable

or whole episodes at once with :func:`insert_episodes`. The ``E`` slots being written are
``(ptr + arange(E)) % capacity``; the capacity need not be a multiple of ``E``. Once full, the
oldest episodes are overwritten first (FIFO). While episodes are being written (after an
``insert_step``, before ``finish_episodes``) their slots are excluded from sampling, so only
complete episodes are ever sampled.

Sampling (:func:`sample`) follows DHRL's low-level HER sampler, ``sample_her_transitions`` in
jayLEE0301/dhrl_official ``DHRL/rl/replay/planner.py``: see :func:`sample_indices`. The
high-level replay of DHRL (``HighReplay`` in the same file) is the same sampler on a second
buffer whose episodes are the ``ceil(T / k)`` subgoal-level transitions, with ``future_p = 1``
and ``future_step = high_future_step`` (15); its subgoal testing (action relabelling and
penalties) needs rewards and the graph, so it belongs to the caller.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

Array = jax.Array
Spec = Mapping[str, Any]  # name -> one step's example array or jax.ShapeDtypeStruct (no T, E axes)

#: Names :func:`gather` adds to a batch besides the fields and their ``next_`` versions.
INDEX_KEYS = ("slot", "t", "offset", "relabelled")


@struct.dataclass
class ReplayState:
    """A ring of ``capacity`` episodes of ``horizon`` steps, written ``num_envs`` at a time.

    ``states[k]`` is ``[capacity, horizon + 1, ...]``, ``transitions[k]`` ``[capacity, horizon,
    ...]``. ``ptr`` is the first slot of the episodes being (or next to be) written, ``count``
    the number of complete episodes stored (at most ``capacity``), ``writing`` whether
    ``insert_step`` has started overwriting the slots at ``ptr`` since the last finish.
    """

    states: dict[str, Array]
    transitions: dict[str, Array]
    ptr: Array  # int32 []
    count: Array  # int32 []
    writing: Array  # bool []
    capacity: int = struct.field(pytree_node=False)
    horizon: int = struct.field(pytree_node=False)
    num_envs: int = struct.field(pytree_node=False)


@struct.dataclass
class HerIndices:
    """Where a sampled batch comes from: episode slot, time ``t``, HER offset and mask.

    ``offset`` is ``f = future_t - t`` (``>= 1``); the relabelled goal is the achieved goal of
    state ``t + f``. (DHRL's ``batch['offset']`` is ``f - 1``.)
    """

    slot: Array  # int32 [B]
    t: Array  # int32 [B]
    offset: Array  # int32 [B]
    relabelled: Array  # bool [B]


def _shape_dtype(x: Any) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and (canonical, x64-aware) dtype of an example array or ShapeDtypeStruct."""
    if not (hasattr(x, "shape") and hasattr(x, "dtype")):
        x = np.asarray(x)
    return tuple(x.shape), jax.dtypes.canonicalize_dtype(x.dtype)


def init(
    capacity: int,
    horizon: int,
    num_envs: int,
    state_spec: Spec,
    transition_spec: Spec,
) -> ReplayState:
    """Allocate an empty buffer of ``capacity`` episodes of ``horizon`` steps.

    ``state_spec`` / ``transition_spec`` map field names to an example of ONE step of the field
    (an array or ``jax.ShapeDtypeStruct``, without time or env axes), e.g.
    ``{"obs": jax.ShapeDtypeStruct((30,), jnp.float32), "torso_z": jnp.float32(0)}``.
    """
    if capacity < num_envs or num_envs < 1 or horizon < 1:
        raise ValueError(f"need capacity >= num_envs >= 1 and horizon >= 1, got "
                         f"{capacity=}, {num_envs=}, {horizon=}")
    names = list(state_spec) + list(transition_spec)
    out_names = names + [f"next_{k}" for k in state_spec] + list(INDEX_KEYS)
    out_names += [f"future_{k}" for k in state_spec]
    if len(set(out_names)) != len(out_names):
        raise ValueError(f"field names clash (with each other or with next_*/future_*/"
                         f"{INDEX_KEYS}): {names}")

    def alloc(spec: Spec, length: int) -> dict[str, Array]:
        out = {}
        for k, x in spec.items():
            shape, dtype = _shape_dtype(x)
            out[k] = jnp.zeros((capacity, length, *shape), dtype)
        return out

    return ReplayState(
        states=alloc(state_spec, horizon + 1),
        transitions=alloc(transition_spec, horizon),
        ptr=jnp.zeros((), jnp.int32),
        count=jnp.zeros((), jnp.int32),
        writing=jnp.zeros((), jnp.bool_),
        capacity=capacity,
        horizon=horizon,
        num_envs=num_envs,
    )


def _write_slots(state: ReplayState, n: int) -> Array:
    """The ``n`` ring slots starting at ``ptr`` (wrapping around)."""
    return (state.ptr + jnp.arange(n, dtype=jnp.int32)) % state.capacity


def _check_keys(data: Mapping[str, Array], expected: list[str], allowed: list[str]) -> None:
    missing = [k for k in expected if k not in data]
    unknown = [k for k in data if k not in allowed]
    if missing or unknown:
        raise KeyError(f"missing fields {missing}, unknown fields {unknown}")


def insert_step(state: ReplayState, t: int | Array, step: Mapping[str, Array]) -> ReplayState:
    """Write time index ``t`` (0 <= t < T) of the ``E`` episodes being filled.

    ``step`` holds every field (per-state and per-transition) with leading axis ``E``:
    the state at ``t`` and what was done at ``t``. Marks the slots as being written.
    """
    names = list(state.states) + list(state.transitions)
    _check_keys(step, names, names)
    slots = _write_slots(state, state.num_envs)

    def put(buf: dict[str, Array]) -> dict[str, Array]:
        return {k: v.at[slots, t].set(step[k], unique_indices=True) for k, v in buf.items()}

    return state.replace(states=put(state.states), transitions=put(state.transitions),
                         writing=jnp.ones((), jnp.bool_))


def insert_final(state: ReplayState, final: Mapping[str, Array]) -> ReplayState:
    """Write the final state (index ``T``) of the ``E`` episodes being filled.

    ``final`` holds the per-state fields with leading axis ``E``; per-transition fields in it are
    ignored, so the caller may pass the same kind of dict as to :func:`insert_step`.
    """
    _check_keys(final, list(state.states), list(state.states) + list(state.transitions))
    slots = _write_slots(state, state.num_envs)
    states = {k: v.at[slots, state.horizon].set(final[k], unique_indices=True)
              for k, v in state.states.items()}
    return state.replace(states=states, writing=jnp.ones((), jnp.bool_))


def _advance(state: ReplayState, n: int) -> ReplayState:
    return state.replace(ptr=(state.ptr + n) % state.capacity,
                         count=jnp.minimum(state.count + n, state.capacity),
                         writing=jnp.zeros((), jnp.bool_))


def finish_episodes(state: ReplayState) -> ReplayState:
    """Declare the ``E`` episodes at ``ptr`` complete: advance ``ptr`` by ``E``, grow ``count``."""
    return _advance(state, state.num_envs)


def insert_episodes(state: ReplayState, episodes: Mapping[str, Array]) -> ReplayState:
    """Write ``N`` (<= capacity) complete episodes at once and advance ``ptr`` by ``N``.

    ``episodes`` holds every field: per-state ones ``[N, T + 1, ...]``, per-transition ones
    ``[N, T, ...]``. Do not call it between ``insert_step`` and ``finish_episodes``.
    """
    names = list(state.states) + list(state.transitions)
    _check_keys(episodes, names, names)
    n = episodes[names[0]].shape[0]
    if n > state.capacity:
        raise ValueError(f"cannot insert {n} episodes into a buffer of {state.capacity}")
    slots = _write_slots(state, n)

    def put(buf: dict[str, Array]) -> dict[str, Array]:
        return {k: v.at[slots].set(episodes[k], unique_indices=True) for k, v in buf.items()}

    state = state.replace(states=put(state.states), transitions=put(state.transitions))
    return _advance(state, n).replace(writing=state.writing)


def num_sampleable(state: ReplayState) -> Array:
    """Number of complete episodes not being overwritten: the most recent ones before ``ptr``."""
    in_flight = jnp.where(state.writing, state.num_envs, 0)
    return jnp.minimum(state.count, state.capacity - in_flight)


def stored_mask(state: ReplayState) -> Array:
    """``bool[capacity]``: the slots :func:`sample_indices` draws from (the
    :func:`num_sampleable` most recent complete episodes before ``ptr``)."""
    back = (state.ptr - 1 - jnp.arange(state.capacity)) % state.capacity
    return back < num_sampleable(state)


def sample_indices(
    state: ReplayState,
    key: Array,
    batch_size: int,
    *,
    future_p: float | Array,
    future_step: int | Array | None = None,
) -> HerIndices:
    """Draw ``batch_size`` transitions uniformly over (complete episode, t) and HER offsets.

    Rule of DHRL's ``sample_her_transitions`` (jayLEE0301/dhrl_official,
    ``DHRL/rl/replay/planner.py``; ``DHRL/rl/replay/core.py`` is the same without the window):

    * episode uniform over the stored episodes, ``t`` uniform in ``0 .. T-1``;
    * ``relabelled = U < future_p`` (independent per sample);
    * window ``w = min(T - t, future_step)`` (``w = T - t`` when ``future_step`` is None, as in
      core.py); DHRL draws ``f - 1 = floor(U' * w)`` and reads ``ag[t + 1 + (f - 1)]``, i.e.
      ``f`` uniform in ``1 .. w``: the future state ``t + f`` is at least the next state and
      at most the final state ``T``. (We draw the same uniform integers from random bits.)

    Returns slot/offset arrays for every sample, relabelled or not. If no episode is
    sampleable (``num_sampleable(state) == 0``) the indices point at slot garbage: gate use.
    """
    n = num_sampleable(state)
    # One threefry draw for everything (separate randint/uniform calls each add their own XLA
    # compile time). ``bits % m`` is uniform on 0..m-1 up to a bias below m / 2**32.
    bits = jax.random.bits(key, (4, batch_size), jnp.uint32)
    i = (bits[0] % jnp.maximum(n, 1).astype(jnp.uint32)).astype(jnp.int32)
    slot = (state.ptr - n + i) % state.capacity  # the n most recent complete episodes
    t = (bits[1] % jnp.uint32(state.horizon)).astype(jnp.int32)
    window = state.horizon - t
    if future_step is not None:
        window = jnp.minimum(window, future_step)
    offset = 1 + (bits[2] % window.astype(jnp.uint32)).astype(jnp.int32)
    u = (bits[3] >> 8).astype(jnp.float32) * 2.0**-24  # uniform on [0, 1), 24-bit grid
    relabelled = u < future_p
    return HerIndices(slot=slot, t=t, offset=offset, relabelled=relabelled)


def _read(state: ReplayState, slot: Array, t: Array) -> dict[str, Array]:
    """Transition ``t`` of episode ``slot``: per-state fields ``x`` (state ``t``) and
    ``next_x`` (state ``t + 1``), per-transition fields at ``t``."""
    out: dict[str, Array] = {}
    for k, v in state.states.items():
        out[k] = v[slot, t]
        out[f"next_{k}"] = v[slot, t + 1]
    for k, v in state.transitions.items():
        out[k] = v[slot, t]
    return out


def gather(
    state: ReplayState,
    idx: HerIndices,
    *,
    goal_key: str = "goal",
    achieved_key: str = "achieved_goal",
) -> dict[str, Array]:
    """Read the transitions ``idx`` points at and relabel ``goal_key`` where ``idx.relabelled``.

    Returns, with leading axis B: every per-state field ``x`` (state ``t``) and ``next_x``
    (state ``t + 1``); every per-transition field at ``t``, with ``goal_key`` replaced by the
    achieved goal of state ``t + offset`` where relabelled; ``future_<achieved_key>`` (that
    achieved goal, for every sample, as DHRL's ``future_ag``); and ``slot``, ``t``, ``offset``,
    ``relabelled``.
    """
    if achieved_key not in state.states or goal_key not in state.transitions:
        raise KeyError(f"need per-state {achieved_key!r} and per-transition {goal_key!r}")
    out = _read(state, idx.slot, idx.t)
    future = state.states[achieved_key][idx.slot, idx.t + idx.offset]
    mask = idx.relabelled.reshape(idx.relabelled.shape + (1,) * (future.ndim - 1))
    out[goal_key] = jnp.where(mask, future, out[goal_key])
    out[f"future_{achieved_key}"] = future
    out.update(slot=idx.slot, t=idx.t, offset=idx.offset, relabelled=idx.relabelled)
    return out


def gather_ahead(state: ReplayState, idx: HerIndices, i: int | Array) -> dict[str, Array]:
    """The transition ``i`` steps after each of ``idx``'s, in the same episode: every
    per-state field ``x`` at ``t + i`` and ``next_x`` at ``t + i + 1``, every per-transition
    field at ``t + i``, and ``valid`` (``t + i < T``: the episode has that step). Past the
    episode's end the last transition stands in (its ``valid`` is False); goals are not
    relabelled (the caller keeps its batch's). For n-step targets."""
    out = _read(state, idx.slot, jnp.minimum(idx.t + i, state.horizon - 1))
    out["valid"] = idx.t + i < state.horizon
    return out


def sample(
    state: ReplayState,
    key: Array,
    batch_size: int,
    *,
    future_p: float | Array,
    future_step: int | Array | None = None,
    goal_key: str = "goal",
    achieved_key: str = "achieved_goal",
) -> dict[str, Array]:
    """HER batch: :func:`sample_indices` then :func:`gather` (see both for the rule and keys).

    DHRL's low level uses ``future_p=0.8, future_step=150``; its high level (on a buffer of
    subgoal-level episodes) ``future_p=1.0, future_step=15``.
    """
    with jax.named_scope("her_sample"):
        idx = sample_indices(state, key, batch_size, future_p=future_p,
                             future_step=future_step)
        return gather(state, idx, goal_key=goal_key, achieved_key=achieved_key)
