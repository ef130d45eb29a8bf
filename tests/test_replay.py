"""Tests of the HER replay buffer (flrjax/replay.py) against a NumPy reference.

Every stored value encodes where it comes from, so each sampled transition can be checked
exactly: per-state fields of episode ``e`` at state ``t`` hold ``(e, t)``, per-transition fields
a different code of ``(e, t)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from flrjax import replay

T = 8  # episode length
E = 4  # envs in lockstep
C = 10  # capacity in episodes: not a multiple of E, so the ring wraps mid-batch
STATE_SPEC = {
    "obs": jax.ShapeDtypeStruct((3,), jnp.float32),
    "achieved_goal": jax.ShapeDtypeStruct((2,), jnp.float32),
    "torso_z": jax.ShapeDtypeStruct((), jnp.float32),
}
TRANSITION_SPEC = {
    "action": jax.ShapeDtypeStruct((2,), jnp.float32),
    "goal": jax.ShapeDtypeStruct((2,), jnp.float32),
    "step": jax.ShapeDtypeStruct((), jnp.int32),
}


def episodes_np(ep_ids: np.ndarray, base: float = 0.0) -> dict[str, np.ndarray]:
    """Whole episodes ``[N, T(+1), ...]`` whose values encode (episode id, t)."""
    e = np.asarray(ep_ids, np.float32)[:, None] + base
    ts = np.arange(T + 1, dtype=np.float32)[None, :]
    es = np.broadcast_to(e, (len(ep_ids), T + 1))
    tt = np.broadcast_to(ts, es.shape)
    return {
        "obs": np.stack([es, tt, es * 100 + tt], -1),
        "achieved_goal": np.stack([es, tt], -1),
        "torso_z": es * 1000 + tt,
        "action": np.stack([es, -tt], -1)[:, :T],
        "goal": np.stack([-1 - es, tt], -1)[:, :T],  # never equal to an achieved goal
        "step": np.broadcast_to(np.arange(T, dtype=np.int32), (len(ep_ids), T)).copy(),
    }


def empty() -> replay.ReplayState:
    return replay.init(C, T, E, STATE_SPEC, TRANSITION_SPEC)


insert_step = jax.jit(replay.insert_step)
insert_final = jax.jit(replay.insert_final)
finish = jax.jit(replay.finish_episodes)
insert_episodes = jax.jit(replay.insert_episodes)
sample = jax.jit(replay.sample, static_argnames=("batch_size", "future_step"))


def write_round(state: replay.ReplayState, ep_ids: np.ndarray, steps: int = T,
                done: bool = True) -> replay.ReplayState:
    """Write ``steps`` steps (and, if ``done``, the final state) of E episodes step by step."""
    eps = episodes_np(ep_ids)
    for t in range(steps):
        state = insert_step(state, t, {k: v[:, t] for k, v in eps.items()})
    if done:
        state = insert_final(state, {k: eps[k][:, T] for k in STATE_SPEC})
        state = finish(state)
    return state


def check_batch(b: dict[str, np.ndarray], allowed_ids: set[int], window: int | None,
                base: float = 0.0) -> None:
    """Every sampled transition is consistent with the episode encoded in its obs."""
    b = jax.tree.map(np.asarray, b)
    e = b["obs"][:, 0] - base
    t = b["t"]
    f = b["offset"]
    assert set(np.unique(e).astype(int)) <= allowed_ids
    ref = episodes_np(e.astype(int), base)
    rows = np.arange(len(t))
    for k in STATE_SPEC:
        np.testing.assert_array_equal(b[k], ref[k][rows, t])
        np.testing.assert_array_equal(b[f"next_{k}"], ref[k][rows, t + 1])
    for k in ("action", "step"):
        np.testing.assert_array_equal(b[k], ref[k][rows, t])
    w = T - t if window is None else np.minimum(T - t, window)
    assert np.all((f >= 1) & (f <= w))
    future = ref["achieved_goal"][rows, t + f]
    np.testing.assert_array_equal(b["future_achieved_goal"], future)
    rel = b["relabelled"][:, None]
    np.testing.assert_array_equal(b["goal"], np.where(rel, future, ref["goal"][rows, t]))


@pytest.mark.parametrize("window", [3, None])
def test_sample_matches_reference_rule(window: int | None) -> None:
    state = empty()
    state = write_round(state, np.arange(0, 4))
    state = write_round(state, np.arange(4, 8))
    n, p = 100_000, 0.8
    b = sample(state, jax.random.key(0), batch_size=n, future_p=p, future_step=window)
    check_batch(b, set(range(8)), window)

    # Episodes and t uniform, f uniform in 1..min(window, T - t): chi-square on (e, t, f).
    e, t, f = (np.asarray(b[k]).astype(int) for k in ("obs", "t", "offset"))
    e = e[:, 0]
    w = T - np.arange(T) if window is None else np.minimum(T - np.arange(T), window)
    counts = np.zeros((8, T, T + 1))
    np.add.at(counts, (e, t, f), 1)
    prob = np.zeros_like(counts)
    for ti in range(T):
        prob[:, ti, 1 : w[ti] + 1] = 1 / 8 / T / w[ti]
    assert counts[prob == 0].sum() == 0  # f never 0, never past the window or the episode end
    assert stats.chisquare(counts[prob > 0], prob[prob > 0] * n).pvalue > 1e-3

    frac = np.asarray(b["relabelled"]).mean()
    assert abs(frac - p) < 5 * np.sqrt(p * (1 - p) / n)


def test_insert_episodes_equals_stepwise_and_wraps() -> None:
    stepwise, whole = empty(), empty()
    for r in range(3):  # 12 episodes into 10 slots: the third batch wraps to slots 8, 9, 0, 1
        ids = np.arange(4 * r, 4 * r + 4)
        stepwise = write_round(stepwise, ids)
        whole = insert_episodes(whole, episodes_np(ids))
    jax.tree.map(np.testing.assert_array_equal, stepwise, whole)
    assert int(whole.ptr) == 2 and int(whole.count) == C
    # Oldest episodes 0, 1 were overwritten by 10, 11; slot s otherwise holds episode s.
    slot_ids = np.asarray(whole.states["obs"][:, 0, 0]).astype(int)
    np.testing.assert_array_equal(slot_ids, [10, 11, 2, 3, 4, 5, 6, 7, 8, 9])


def test_gather_ahead_reads_the_same_episode_i_steps_later() -> None:
    """gather_ahead(i): per-state fields at t + i and t + i + 1, per-transition ones at t + i,
    of the sampled episode; past its end the last transition, marked not valid."""
    state = insert_episodes(empty(), episodes_np(np.arange(6)))
    idx = replay.sample_indices(state, jax.random.key(0), 64, future_p=0.5)
    slot, t = np.asarray(idx.slot), np.asarray(idx.t)
    for i in (0, 1, 3, T):
        ahead = jax.jit(replay.gather_ahead)(state, idx, i)
        at = np.minimum(t + i, T - 1)
        np.testing.assert_array_equal(ahead["valid"], t + i < T)
        np.testing.assert_array_equal(ahead["achieved_goal"], np.stack([slot, at], -1))
        np.testing.assert_array_equal(ahead["next_obs"][:, 1], at + 1)
        np.testing.assert_array_equal(ahead["action"], np.stack([slot, -at], -1))
        np.testing.assert_array_equal(ahead["goal"], np.stack([-1 - slot, at], -1))
    assert not ahead["valid"].any() and ahead["valid"].dtype == bool


def stored_ids(state: replay.ReplayState) -> set[int]:
    """The episodes in the slots :func:`replay.stored_mask` marks (by the ids they hold)."""
    mask = np.asarray(replay.stored_mask(state))
    return set(np.asarray(state.states["obs"][:, 0, 0])[mask].astype(int))


def test_only_complete_episodes_are_sampled() -> None:
    """Sampling draws from the complete episodes not being overwritten, and stored_mask marks
    exactly those."""
    state = empty()
    assert int(replay.num_sampleable(state)) == 0 and stored_ids(state) == set()
    state = write_round(state, np.arange(0, 4), steps=3, done=False)
    assert int(replay.num_sampleable(state)) == 0  # first batch still being written
    assert stored_ids(state) == set()

    for r in range(3):
        state = write_round(state, np.arange(4 * r, 4 * r + 4))
    assert int(replay.num_sampleable(state)) == C
    b = sample(state, jax.random.key(1), batch_size=4000, future_p=0.5, future_step=3)
    check_batch(b, set(range(2, 12)), 3)
    assert set(np.asarray(b["obs"][:, 0]).astype(int)) == set(range(2, 12)) == stored_ids(state)

    # Mid-episode: slots 2..5 (episodes 2..5) are being overwritten by episodes 12..15.
    state = write_round(state, np.arange(12, 16), steps=4, done=False)
    assert int(replay.num_sampleable(state)) == C - E
    b = sample(state, jax.random.key(2), batch_size=4000, future_p=0.5, future_step=3)
    check_batch(b, set(range(6, 12)), 3)
    assert set(np.asarray(b["obs"][:, 0]).astype(int)) == set(range(6, 12)) == stored_ids(state)

    # Finish them (steps 4..T-1 and the final state): now the newest 10 are 6..15.
    eps = episodes_np(np.arange(12, 16))
    for t in range(4, T):
        state = insert_step(state, t, {k: v[:, t] for k, v in eps.items()})
    state = finish(insert_final(state, {k: eps[k][:, T] for k in STATE_SPEC}))
    b = sample(state, jax.random.key(3), batch_size=4000, future_p=0.5, future_step=3)
    check_batch(b, set(range(6, 16)), 3)
    assert set(np.asarray(b["obs"][:, 0]).astype(int)) == set(range(6, 16)) == stored_ids(state)


def test_bad_fields_rejected() -> None:
    with pytest.raises(ValueError, match="clash"):
        replay.init(C, T, E, {"obs": jnp.zeros(3), "next_obs": jnp.zeros(3)}, {})
    with pytest.raises(KeyError, match="missing"):
        replay.insert_step(empty(), 0, {"obs": jnp.zeros((E, 3))})


def rollout_and_sample(seed_base: jax.Array, key: jax.Array, future_p: jax.Array
                       ) -> dict[str, jax.Array]:
    """A scanned 'trainer': 3 rounds of E episodes written step by step, then one sample."""
    ids = np.arange(12)
    at0, at1 = episodes_np(ids, 0.0), episodes_np(ids, 1.0)  # every field is affine in base
    eps = {k: (at0[k] + seed_base * (at1[k] - at0[k])).astype(at0[k].dtype) for k in at0}
    eps = {k: v.reshape(3, E, *v.shape[1:]) for k, v in eps.items()}

    def one_round(state, ep):
        def one_step(s, t):
            return replay.insert_step(s, t, {k: v[:, t] for k, v in ep.items()}), None

        state, _ = jax.lax.scan(one_step, state, jnp.arange(T))
        state = replay.insert_final(state, {k: ep[k][:, T] for k in STATE_SPEC})
        return replay.finish_episodes(state), None

    state, _ = jax.lax.scan(one_round, empty(), eps)
    return replay.sample(state, key, 2000, future_p=future_p, future_step=3)


def test_scan_vmap_jit_over_seeds() -> None:
    # Episode ids shift by 1000 * seed, so each seed's batch must come from its own data.
    bases = jnp.array([0.0, 1000.0, 2000.0])
    keys = jax.random.split(jax.random.key(4), 3)
    ps = jnp.array([0.0, 0.5, 1.0])  # traced future_p, different per seed
    batched = jax.tree.map(np.asarray, jax.jit(jax.vmap(rollout_and_sample))(bases, keys, ps))
    for s in range(3):
        b = {k: v[s] for k, v in batched.items()}
        check_batch(b, set(range(2, 12)), 3, base=float(bases[s]))
    rel = batched["relabelled"].mean(axis=1)
    assert rel[0] == 0.0 and rel[2] == 1.0 and abs(rel[1] - 0.5) < 0.06
    # Same result without vmap.
    single = jax.jit(rollout_and_sample)(bases[1], keys[1], ps[1])
    jax.tree.map(lambda x, y: np.testing.assert_array_equal(x[1], y), batched, single)
