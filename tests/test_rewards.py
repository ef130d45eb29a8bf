"""Tests for flrjax.rewards: eq. (1), HIGL dense reward, FLR eq. (5), sampling, checks."""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import rewards as R

GAMMA = 0.99
V_LOW = -1.0 / (1.0 - GAMMA)  # lower bound of V (paper §2.2)


def value_fn(obs: jax.Array, goals: jax.Array) -> jax.Array:
    """Toy V_l(s', sg') in [−1/(1−γ), 0]: falls with the distance of sg' from obs[..., :2]."""
    dist = jnp.linalg.norm(obs[:, None, :2] - goals, axis=-1)
    return V_LOW * jnp.tanh(dist / 4.0)


# Jitted once per shape; the tests reuse a few shapes (B=64, M=8) to keep compiles few.
flr = jax.jit(R.forward_looking_reward, static_argnums=0, static_argnames="v_min")
sample = jax.jit(R.sample_next_subgoals, static_argnames="num")
B, M = 64, 8


def key(seed: int) -> jax.Array:
    """PRNG key for the sampling tests: 'rbg' compiles ~2x faster than the default threefry on
    CPU (the sampler is impl-agnostic); test_jit_and_vmap_over_seeds uses threefry."""
    return jax.random.key(seed, impl="rbg")


def value_np(obs: np.ndarray, goal: np.ndarray) -> float:
    return float(V_LOW * np.tanh(np.linalg.norm(obs[:2] - goal) / 4.0))


def brute_force_flr(obs, next_ag, subgoal, cands, *, alpha, eps, delta, fallback=0.0):
    """Eq. (5) as a NumPy double loop over transitions and candidates."""
    out = np.empty(len(obs))
    for b in range(len(obs)):
        if np.linalg.norm(next_ag[b] - subgoal[b]) >= delta:
            out[b] = -1.0
            continue
        best = None
        for m in range(cands.shape[1]):
            if np.linalg.norm(cands[b, m] - subgoal[b]) >= eps - R.DIST_TOL:
                v = value_np(obs[b], cands[b, m])
                best = v if best is None else max(best, v)
        out[b] = fallback if best is None else alpha * best
    return out


def random_batch(seed: int, batch: int = B, num: int = M, delta: float = 0.5, eps: float = 2.0):
    """Random transitions: ~half reach their subgoal; candidates on both sides of eps."""
    rng = np.random.default_rng(seed)
    subgoal = rng.uniform(-10, 10, (batch, 2))
    offset_dir = rng.normal(size=(batch, 2))
    offset_dir /= np.linalg.norm(offset_dir, axis=-1, keepdims=True)
    # Half reaching (distance < delta), half not; keep clear of the threshold itself.
    reach = rng.random(batch) < 0.5
    radius = np.where(reach, rng.uniform(0, 0.9 * delta, batch), rng.uniform(1.1 * delta, 3, batch))
    next_ag = subgoal + radius[:, None] * offset_dir
    obs = np.concatenate([next_ag, rng.normal(size=(batch, 5))], axis=-1)
    cand_dir = rng.normal(size=(batch, num, 2))
    cand_dir /= np.linalg.norm(cand_dir, axis=-1, keepdims=True)
    cand_r = rng.choice([0.3 * eps, 0.8 * eps, 1.2 * eps, 2.0 * eps], size=(batch, num))
    cands = subgoal[:, None] + cand_r[..., None] * cand_dir
    # Transition 0 reaches but has no qualifying candidate; transition 1 reaches, all qualify.
    next_ag[0], obs[0, :2] = subgoal[0], subgoal[0]
    cands[0] = subgoal[0] + 0.5 * eps * cand_dir[0]
    next_ag[1], obs[1, :2] = subgoal[1] + 0.1, subgoal[1] + 0.1
    cands[1] = subgoal[1] + 1.5 * eps * cand_dir[1]
    return [a.astype(np.float32) for a in (obs, next_ag, subgoal, cands)]


# --- eq. (1) and the HIGL dense reward -------------------------------------------------------


def test_sparse_reward_hand_cases():
    goal = jnp.array([1.0, 2.0])
    achieved = jnp.array([[1.0, 2.0], [1.5, 2.0], [1.3, 2.0], [1.0, 2.5], [4.0, -2.0]])
    # distances 0, 0.5, 0.3, 0.5, 5: strict "< delta" as in eq. (1)
    np.testing.assert_array_equal(R.sparse_reward(achieved, goal), [0, -1, 0, -1, -1])
    np.testing.assert_array_equal(R.sparse_reward(achieved, goal, delta=0.6), [0, 0, 0, 0, -1])
    # any leading batch shape
    batch = jnp.zeros((3, 4, 2))
    assert R.sparse_reward(batch, jnp.zeros(2)).shape == (3, 4)
    assert R.sparse_reward(batch, jnp.zeros(2)).dtype == jnp.float32


def test_dense_reward_hand_cases():
    achieved = jnp.array([[0.0, 0.0], [3.0, 4.0]])
    goal = jnp.array([[0.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(R.dense_reward(achieved, goal), [0.0, -5.0])
    np.testing.assert_allclose(R.dense_reward(achieved, goal, scale=0.1), [0.0, -0.5])
    # HIGL relative subgoals: goal = ag + subgoal
    ag, sub, next_ag = jnp.array([1.0, 1.0]), jnp.array([3.0, 0.0]), jnp.array([1.0, 1.0])
    np.testing.assert_allclose(R.dense_reward(next_ag, ag + sub), -3.0)


# --- FLR, eq. (5) ----------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_flr_matches_brute_force(seed):
    alpha, eps, delta = 0.01, 2.0, 0.5
    obs, next_ag, subgoal, cands = random_batch(seed, eps=eps, delta=delta)
    out = flr(value_fn, obs, next_ag, subgoal, cands, alpha=alpha, eps=eps, delta=delta)
    expected = brute_force_flr(obs, next_ag, subgoal, cands, alpha=alpha, eps=eps, delta=delta)
    np.testing.assert_allclose(out.reward, expected, rtol=1e-5, atol=1e-6)
    reached = np.linalg.norm(next_ag - subgoal, axis=-1) < delta
    np.testing.assert_array_equal(out.reached, reached)
    # the batch really covers all branches
    num_q = np.asarray(out.num_qualified)
    assert reached.any() and (~reached).any()
    assert num_q[0] == 0 and out.reward[0] == 0.0  # reaching, no candidate: sparse fallback
    assert np.isneginf(out.best_value[0])
    assert num_q[1] == M  # reaching, all qualify
    assert (reached & (num_q > 0) & (num_q < M)).any()  # reaching, some masked
    np.testing.assert_array_equal(np.asarray(out.reward)[~reached], -1.0)


def test_flr_no_candidate_fallback_is_configurable():
    obs, next_ag, subgoal, cands = random_batch(3)
    out = flr(value_fn, obs, next_ag, subgoal, cands, alpha=0.01, eps=2.0, no_candidate_reward=-0.5)
    expected = brute_force_flr(
        obs, next_ag, subgoal, cands, alpha=0.01, eps=2.0, delta=0.5, fallback=-0.5
    )
    np.testing.assert_allclose(out.reward, expected, rtol=1e-5, atol=1e-6)
    assert out.reward[0] == -0.5


def test_flr_hand_case_picks_max_over_qualifying():
    # s' at the subgoal; candidates at distances 1 (masked, highest V), 2 and 3 from it.
    subgoal = jnp.zeros((1, 2))
    cands = jnp.array([[[1.0, 0.0], [0.0, 2.0], [-3.0, 0.0]]])
    obs = jnp.zeros((1, 4))
    out = flr(value_fn, obs, subgoal, subgoal, cands, alpha=0.01, eps=2.0, delta=0.5)
    np.testing.assert_allclose(out.reward, [0.01 * V_LOW * np.tanh(0.5)], rtol=1e-6)
    assert int(out.num_qualified[0]) == 2 and bool(out.reached[0])
    # eps = 0 (mask off) lets the distance-1 candidate win
    off = flr(value_fn, obs, subgoal, subgoal, cands, alpha=0.01, eps=0.0)
    np.testing.assert_allclose(off.reward, [0.01 * V_LOW * np.tanh(0.25)], rtol=1e-6)
    # 0.6 away from the subgoal: not reached, -1 whatever the candidates
    miss = flr(value_fn, obs, subgoal + 0.6, subgoal, cands, alpha=0.01, eps=2.0, delta=0.5)
    np.testing.assert_array_equal(miss.reward, [-1.0])


def test_flr_candidate_at_exactly_eps_qualifies():
    # Sampling "at a distance of eps" (width=0) must not lose candidates to rounding.
    subgoal = np.full((B, 2), 13.7, np.float32)
    cands = sample(key(0), subgoal, eps=2.0, num=M, width=0.0)
    assert bool(R.candidate_mask(subgoal, cands, eps=2.0).all())


def test_flr_v_min_clips_values():
    def overshooting(obs, goals):
        return jnp.full(goals.shape[:2], 5.0 * V_LOW)

    obs, next_ag, subgoal, cands = random_batch(4)
    raw = flr(overshooting, obs, next_ag, subgoal, cands, alpha=1 - GAMMA, eps=2.0)
    hit = np.asarray(raw.reached & (raw.num_qualified > 0))
    assert hit.any() and (np.asarray(raw.reward)[hit] < -1).all()
    clipped = flr(overshooting, obs, next_ag, subgoal, cands, alpha=1 - GAMMA, eps=2.0, v_min=V_LOW)
    np.testing.assert_allclose(np.asarray(clipped.reward)[hit], -1.0, rtol=1e-5)


def test_flr_final_goal_ablation():
    # The final goal lies within eps of the subgoal: eps=0 must still use it.
    subgoal = jnp.zeros((2, 2))
    goal = jnp.array([[1.0, 0.0], [0.0, 1.0]])
    cands = R.next_subgoal_is_goal(goal, num=3)
    assert cands.shape == (2, 3, 2)
    np.testing.assert_array_equal(cands[:, 2], goal)
    obs = jnp.zeros((2, 4))
    out = flr(value_fn, obs, subgoal, subgoal, cands, alpha=0.01, eps=0.0)
    np.testing.assert_array_equal(out.num_qualified, [3, 3])
    np.testing.assert_allclose(out.reward, 0.01 * V_LOW * np.tanh(0.25), rtol=1e-6)
    # with the eps mask on, the same candidates would all be dropped
    masked = flr(value_fn, obs, subgoal, subgoal, cands, alpha=0.01, eps=2.0)
    np.testing.assert_array_equal(masked.num_qualified, [0, 0])


def test_eq4_bound_holds_for_alpha_at_most_one_minus_gamma():
    # Property: all transitions reach their subgoal, candidates up to 200 away (V near its
    # lower bound -1/(1-gamma)); reward >= -1 for every alpha in (0, 1-gamma].
    rng = np.random.default_rng(1)
    for alpha in (1e-3, 0.5 * (1 - GAMMA), 1 - GAMMA):
        for seed in range(4):
            obs = rng.uniform(-50, 50, (B, 3)).astype(np.float32)
            subgoal = obs[:, :2] + rng.uniform(-0.35, 0.35, (B, 2)).astype(np.float32)
            cands = sample(key(seed), subgoal, eps=2.0, num=M, width=200.0)
            out = flr(value_fn, obs, obs[:, :2], subgoal, cands, alpha=alpha, eps=2.0)
            assert bool(out.reached.all()), seed  # only eq. (5)'s top branch
            assert float(out.reward.min()) >= -1.0 - 1e-6, (alpha, seed)
            assert float(out.reward.max()) <= 0.0


def test_alpha_above_one_minus_gamma_can_go_below_minus_one():
    # Far candidates have V close to -1/(1-gamma); alpha = 10 (1-gamma) makes alpha V < -1.
    subgoal = jnp.zeros((1, 2))
    cands = jnp.array([[[100.0, 0.0], [0.0, 120.0], [-90.0, 0.0]]])
    obs = jnp.zeros((1, 4))
    out = flr(value_fn, obs, subgoal, subgoal, cands, alpha=10 * (1 - GAMMA), eps=2.0)
    assert bool(out.reached[0])
    assert float(out.reward[0]) < -1.0  # reaching the subgoal now pays less than missing it


# --- sampling --------------------------------------------------------------------------------


@pytest.mark.parametrize("dim", [2, 3])
def test_sample_next_subgoals_ring(dim):
    subgoal = np.random.default_rng(8).uniform(-10, 10, (B, dim)).astype(np.float32)
    eps, width = 2.0, 0.5
    cands = sample(key(7), subgoal, eps=eps, num=M, width=width)
    assert cands.shape == (B, M, dim)
    dist = np.asarray(R.goal_distance(cands, subgoal[..., None, :]))
    assert dist.min() >= eps - 1e-4 and dist.max() <= eps + width + 1e-4
    # uniform in area/volume: mean of r^dim is the midpoint of [eps^dim, (eps+width)^dim]
    mid = 0.5 * (eps**dim + (eps + width) ** dim)
    np.testing.assert_allclose((dist**dim).mean(), mid, rtol=0.02)
    # directions cover the sphere: mean unit vector near 0
    unit = np.asarray(cands - subgoal[..., None, :]) / dist[..., None]
    assert np.abs(unit.reshape(-1, dim).mean(0)).max() < 0.1


# Goal space of the 24 x 8 room; the first half of the subgoals sits 0.5 from its left wall.
LOW, HIGH = np.array([0.0, 0.0], np.float32), np.array([24.0, 8.0], np.float32)
NEAR_WALL = np.where(np.arange(B)[:, None] < B // 2, [0.5, 4.0], [12.0, 4.0]).astype(np.float32)


def test_sample_next_subgoals_deterministic_per_key():
    a = sample(key(0), NEAR_WALL, eps=2.0, num=M, low=LOW, high=HIGH)
    b = sample(key(0), NEAR_WALL, eps=2.0, num=M, low=LOW, high=HIGH)
    c = sample(key(1), NEAR_WALL, eps=2.0, num=M, low=LOW, high=HIGH)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert len(np.unique(np.asarray(a).reshape(-1, 2), axis=0)) == B * M  # no repeats


def test_sample_next_subgoals_clipping_and_default_width():
    cands = sample(key(3), NEAR_WALL, eps=2.0, num=M, low=LOW, high=HIGH)
    assert cands.shape == (B, M, 2)
    assert bool(((cands >= LOW) & (cands <= HIGH)).all())
    dist = np.asarray(R.goal_distance(cands, NEAR_WALL[:, None]))
    assert (dist[: B // 2] < 2.0 - 1e-3).any()  # clipping pulled some inside eps ...
    # ... away from the walls the default ring [eps, 1.25 eps] is untouched ...
    middle = dist[B // 2 :]
    assert middle.min() >= 2.0 - 1e-4 and middle.max() <= 2.5 + 1e-4 and middle.max() > 2.1
    mask = np.asarray(R.candidate_mask(NEAR_WALL, cands, eps=2.0))
    np.testing.assert_array_equal(mask, dist >= 2.0 - R.DIST_TOL)  # ... and FLR drops those
    assert not mask.all()
    obs = np.pad(NEAR_WALL, ((0, 0), (0, 2)))
    out = flr(value_fn, obs, NEAR_WALL, NEAR_WALL, cands, alpha=0.01, eps=2.0)
    np.testing.assert_array_equal(out.num_qualified, mask.sum(-1))


# --- hyper-parameter checks ------------------------------------------------------------------


def test_validate_flr_params():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        R.validate_flr_params(0.01, 0.99, eps=2.0, delta=0.5)  # the paper's setting
        R.validate_flr_params(0.1, 0.9)  # 1 - 0.9 rounds below 0.1: no spurious warning
        R.validate_flr_params(0.01, 0.99, eps=None, delta=0.5)  # final-goal ablation
    with pytest.warns(UserWarning, match="eq. \\(4\\)"):
        R.validate_flr_params(0.1, 0.99)
    with pytest.warns(UserWarning, match="eq. \\(6\\)"):
        R.validate_flr_params(0.01, 0.99, eps=0.5, delta=0.5)  # paper's ablation: warn only
        R.validate_flr_params(0.0, 0.99)  # eq. (1) exactly: a sweep's baseline point
    for bad in (-0.01, float("nan")):
        with pytest.raises(ValueError, match="alpha"):
            R.validate_flr_params(bad, 0.99)
    with pytest.raises(ValueError, match="gamma"):
        R.validate_flr_params(0.01, 1.0)
    with pytest.raises(ValueError, match="eps"):
        R.validate_flr_params(0.01, 0.99, eps=-1.0, delta=0.5)


def test_flr_shape_errors():
    obs, next_ag, subgoal, cands = random_batch(0, batch=4)
    with pytest.raises(ValueError, match="candidates"):
        R.forward_looking_reward(value_fn, obs, next_ag, subgoal, cands[:, 0], alpha=0.01, eps=2.0)
    with pytest.raises(ValueError, match="value_fn"):
        R.forward_looking_reward(
            lambda o, g: g[..., 0, 0], obs, next_ag, subgoal, cands, alpha=0.01, eps=2.0
        )


# --- jit / vmap ------------------------------------------------------------------------------


@pytest.mark.parametrize("reach", ["half", "none", "all"])
def test_flr_chunked_evaluates_only_reaching_transitions_and_matches_brute_force(reach):
    """``chunk`` gives eq. (5)'s rewards with V evaluated on reaching transitions only, at most
    ``chunk`` rows at a time, however many reach."""
    obs, next_ag, subgoal, cands = random_batch(7)
    if reach != "half":  # every transition, or none, within delta of its subgoal
        next_ag = subgoal + (0.1 if reach == "all" else 1.0)
    kw = dict(alpha=0.01, eps=2.0, delta=0.5)
    expected = brute_force_flr(obs, next_ag, subgoal, cands, **kw)
    full = flr(value_fn, obs, next_ag, subgoal, cands, **kw)
    reached = np.asarray(full.reached)
    calls = []

    def counted(o, g):
        calls.append(o.shape[0])  # at trace time: the rows of one evaluation
        return value_fn(o, g)

    for chunk in (1, 5, B - 1):
        calls.clear()
        out = jax.jit(R.forward_looking_reward, static_argnums=0,
                      static_argnames="chunk")(counted, obs, next_ag, subgoal, cands, **kw,
                                               chunk=chunk)
        assert calls == [chunk, chunk]  # traced for its dtype, then in the loop body
        np.testing.assert_allclose(out.reward, expected, rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(out.reward, full.reward)
        np.testing.assert_array_equal(out.best_value[reached], full.best_value[reached])
        assert np.isneginf(np.asarray(out.best_value)[~reached]).all()


@pytest.mark.parametrize("reach", ["half", "none", "all"])
def test_flr_reached_first_asks_for_the_reaching_rows_alone_and_matches_brute_force(reach):
    """``reached_first``: one evaluation of the whole batch with the reaching transitions in
    front and ``rows`` = their count; values past those rows are never read (here: NaN), so
    the rewards are eq. (5)'s and ``best_value`` of the others is −inf. (Under jit and vmap
    through the fused kernel: tests/algos/test_dhrl.py, tests/agents/gc_td3.)"""
    obs, next_ag, subgoal, cands = random_batch(7)
    if reach != "half":
        next_ag = subgoal + (0.1 if reach == "all" else 1.0)
    kw = dict(alpha=0.01, eps=2.0, delta=0.5)
    expected = brute_force_flr(obs, next_ag, subgoal, cands, **kw)
    reached = np.linalg.norm(next_ag - subgoal, axis=-1) < 0.5
    seen = {}

    def front_rows(o, g, rows):
        seen["rows"] = rows
        wanted = jnp.arange(o.shape[0])[:, None] < rows
        return jnp.where(wanted, value_fn(o, g), jnp.nan)  # the rows past `rows` are junk

    out = R.forward_looking_reward(front_rows, obs, next_ag, subgoal, cands, **kw,
                                   reached_first=True)  # eager: `rows` is a number here
    np.testing.assert_allclose(out.reward, expected, rtol=1e-5, atol=1e-6)
    full = R.forward_looking_reward(value_fn, obs, next_ag, subgoal, cands, **kw)  # eager too
    np.testing.assert_array_equal(out.best_value[reached], full.best_value[reached])
    assert np.isneginf(np.asarray(out.best_value)[~reached]).all()
    assert int(seen["rows"]) == reached.sum()


@pytest.mark.parametrize("chunk", [None, 3])
def test_jit_and_vmap_over_seeds(chunk):
    """Per-seed FLR under vmap, also chunked (the while loop runs until every seed's reaching
    transitions are done)."""
    seeds, batch, num = 3, 16, 5
    batches = [random_batch(s, batch=batch, num=num) for s in range(seeds)]
    obs, next_ag, subgoal, _ = (np.stack(x) for x in zip(*batches, strict=True))
    keys = jax.random.split(jax.random.key(0), seeds)

    def step(key, obs, next_ag, subgoal, alpha):
        cands = R.sample_next_subgoals(key, subgoal, eps=2.0, num=num, low=-12.0, high=12.0)
        out = R.forward_looking_reward(
            value_fn, obs, next_ag, subgoal, cands, alpha=alpha, eps=2.0, chunk=chunk
        )
        return out, cands

    alphas = jnp.array([0.001, 0.01, 0.01])  # traced, vmapped alpha (sweeps)
    out, cands = jax.jit(jax.vmap(step))(keys, obs, next_ag, subgoal, alphas)
    assert out.reward.shape == (seeds, batch)
    for s in range(seeds):
        expected = brute_force_flr(
            obs[s],
            next_ag[s],
            subgoal[s],
            np.asarray(cands[s]),
            alpha=float(alphas[s]),
            eps=2.0,
            delta=0.5,
        )
        np.testing.assert_allclose(out.reward[s], expected, rtol=1e-5, atol=1e-6)
    # per-seed keys give different candidates; sparse/dense jit too
    assert not np.allclose(cands[0], cands[1])
    f = jax.jit(functools.partial(R.sparse_reward, delta=0.5))
    np.testing.assert_array_equal(f(next_ag, subgoal), R.sparse_reward(next_ag, subgoal))
    # jit may fuse the norm's sum differently: a few float32 ulps, not the default 1e-7
    np.testing.assert_allclose(
        jax.jit(R.dense_reward)(next_ag, subgoal), R.dense_reward(next_ag, subgoal), rtol=1e-6
    )
