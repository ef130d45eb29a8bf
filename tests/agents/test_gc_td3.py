"""Tests for flrjax.agents.gc_td3 (DHRL's low-level goal-conditioned TD3).

One small config for every test, so each jitted function compiles once per session.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax.agents import gc_td3 as td3

OBS, G, A, B = 4, 2, 2, 64  # obs (its first G entries are the achieved goal), goal, action, batch
CFG = td3.TD3Config(hidden_sizes=(64, 64), lr_actor=1e-3, gamma=0.5)

critic_step = jax.jit(td3.critic_step)
update_actor = jax.jit(td3.update_actor)


def train_step(s, batch, batch_g, key, i):
    """The paper protocol's iteration ``i``: critics (+ distance critics), actor after odd ones."""
    s, m = critic_step(s, batch, key, batch_g)
    if i % CFG.actor_update_freq == CFG.actor_update_freq - 1:
        s, _ = update_actor(s, batch)
    return s, m
act = jax.jit(td3.act)
critic_target = jax.jit(td3.critic_target, static_argnames="critic")


def new_state(seed: int = 0) -> td3.AgentState:
    return td3.init(jax.random.key(seed), OBS, G, A, CFG)


def bandit_batch(rng: np.random.Generator, n: int = B) -> dict[str, np.ndarray]:
    """One-step contextual bandit: the best action is ``goal - obs[:2]``, reward -0.5 * error.

    ``next_obs = obs``, so with any gamma the optimal Q is the reward itself (V* = 0).
    """
    obs = rng.uniform(-0.5, 0.5, (n, OBS)).astype(np.float32)
    goal = rng.uniform(-0.5, 0.5, (n, G)).astype(np.float32)
    action = rng.uniform(-1.0, 1.0, (n, A)).astype(np.float32)
    reward = -0.5 * np.linalg.norm(action - (goal - obs[:, :G]), axis=-1)
    return dict(obs=obs, next_obs=obs, goal=goal, action=action, reward=reward.astype(np.float32))


def leaves_equal(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b),
                                                    strict=True))


# NumPy forward pass of the networks, independent of flax ------------------------------------


def np_mlp(params, x: np.ndarray) -> np.ndarray:
    layers = params["params"]["MLP_0"]
    names = sorted(layers, key=lambda s: int(s.rsplit("_", 1)[1]))
    for i, name in enumerate(names):
        x = x @ np.asarray(layers[name]["kernel"], np.float64) + np.asarray(layers[name]["bias"])
        if i < len(names) - 1:
            x = np.maximum(x, 0.0)
    return x


def np_policy(params, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
    x = np.concatenate([obs, goal - obs[:, :G]], axis=-1)  # relative goal (agent.py)
    return np.tanh(np_mlp(params, x)) * CFG.action_max


def np_q(twin, i: int, obs, goal, action) -> np.ndarray:
    params = jax.tree.map(lambda p: np.asarray(p)[i], twin)
    d = np_mlp(params, np.concatenate([obs, goal, action / CFG.action_max], axis=-1))[:, 0]
    return -(1.0 - CFG.gamma**d) / (1.0 - CFG.gamma)  # DistCritic


# --------------------------------------------------------------------------------------------


def test_init_shapes_and_targets_are_copies():
    s = new_state()
    assert s.step.dtype == jnp.int32 and int(s.step) == 0
    assert leaves_equal(s.actor_params, s.target_actor_params)
    assert leaves_equal(s.critic_params, s.target_critic_params)
    k = s.critic_params["params"]["MLP_0"]["TorchDense_0"]["kernel"]
    assert k.shape == (2, OBS + G + A, 64)
    assert not np.allclose(k[0], k[1])  # twin critics are initialised independently
    assert not np.allclose(k, s.critic_g_params["params"]["MLP_0"]["TorchDense_0"]["kernel"])


def test_act_shapes_bounds_and_explore():
    s = new_state()
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(3, 50, OBS)).astype(np.float32)
    goal = rng.normal(size=(3, 50, G)).astype(np.float32)
    key = jax.random.key(1)
    # one compile: per-row explore flags (shape [3, 50]); the scalar form is used below
    rows = np.ones((3, 50), bool)
    pi = np.asarray(act(s, obs, goal, key, explore=~rows))
    assert pi.shape == (3, 50, A)
    want = np_policy(s.actor_params, obs.reshape(-1, OBS), goal.reshape(-1, G))
    np.testing.assert_allclose(pi, want.reshape(3, 50, A), rtol=1e-4, atol=1e-5)
    noisy = np.asarray(act(s, obs, goal, key, explore=rows))
    assert noisy.shape == (3, 50, A) and np.abs(noisy).max() <= CFG.action_max
    assert not np.allclose(noisy, pi)
    per_row = np.arange(50) % 2 == 0  # explore in every other env only
    mixed = np.asarray(act(s, obs, goal, key, explore=np.broadcast_to(per_row, (3, 50))))
    np.testing.assert_array_equal(mixed[:, per_row], noisy[:, per_row])
    np.testing.assert_array_equal(mixed[:, ~per_row], pi[:, ~per_row])


def test_random_action_probability_and_noise_scale():
    s = new_state()
    rng = np.random.default_rng(0)
    n = 20000
    obs = (0.1 * rng.normal(size=(n, OBS))).astype(np.float32)
    goal = (0.1 * rng.normal(size=(n, G))).astype(np.float32)
    pi = np_policy(s.actor_params, obs, goal).astype(np.float32)
    assert np.abs(pi).max() < 0.7  # so the 0.1 Gaussian noise is (almost) never clipped
    only_random = s.replace(config=dataclasses.replace(CFG, noise_eps=0.0))
    a = np.asarray(act(only_random, obs, goal, jax.random.key(2), explore=True))
    np.testing.assert_allclose(  # and explore=False (a scalar flag) is the policy
        act(only_random, obs, goal, jax.random.key(2), explore=False), pi,
        rtol=1e-4, atol=1e-5)
    replaced = np.any(np.abs(a - pi) > 1e-5, axis=-1)
    assert abs(replaced.mean() - CFG.random_eps) < 0.015  # 4 sigma at n = 20000
    # the replacements are uniform on [-1, 1]: mean 0, std 1/sqrt(3)
    np.testing.assert_allclose(a[replaced].std(), 3**-0.5, rtol=0.05)
    only_noise = s.replace(config=dataclasses.replace(CFG, random_eps=0.0))
    a = np.asarray(act(only_noise, obs, goal, jax.random.key(3), explore=True))
    np.testing.assert_allclose((a - pi).std(), CFG.noise_eps * CFG.action_max, rtol=0.03)


@pytest.mark.parametrize("critic", ["main", "g"])
def test_critic_target_matches_numpy(critic):
    """y = r + gamma * min_i Q'_i(s', pi'(s', g) + noise, g), clipped as learn.py clips."""
    s = new_state()
    # make targets differ from the online nets, so the test sees which ones are used
    s = s.replace(**{f: jax.tree.map(lambda p: np.asarray(p) * 1.5, getattr(s, f)) for f in
                     ("target_actor_params", "target_critic_params", "target_critic_g_params")})
    batch = bandit_batch(np.random.default_rng(0))
    batch["next_obs"] = batch["obs"][::-1].copy()
    batch["reward"][:5] = -200.0  # below -clip_return
    batch["reward"][5:10] = 5.0  # above 0
    key = jax.random.key(4)
    y = np.asarray(critic_target(s, batch, key, critic=critic))

    noise = CFG.target_noise * np.asarray(jax.random.normal(key, (B, A)))
    next_a = np_policy(s.target_actor_params, batch["next_obs"], batch["goal"]) + noise
    twin = s.target_critic_params if critic == "main" else s.target_critic_g_params
    q_next = np.minimum(*(np_q(twin, i, batch["next_obs"], batch["goal"], next_a)
                          for i in range(2)))
    want = batch["reward"] + CFG.gamma * q_next
    want = np.clip(want, -CFG.clip_return, 0.0) if critic == "main" else np.minimum(want, 0.0)
    np.testing.assert_allclose(y, want, rtol=1e-4, atol=1e-5)
    assert np.all(y <= 0.0)
    if critic == "main":
        assert np.all(y[:5] == -CFG.clip_return)
    else:
        assert np.all(y[:5] < -CFG.clip_return)  # the g-critics' target has no lower clip


def test_critic_step_counts_and_polyak_targets_every_10th_step():
    s = new_state()
    rng = np.random.default_rng(0)
    key = jax.random.key(0)
    p = CFG.polyak
    for i in range(21):
        key, k = jax.random.split(key)
        s2, m = critic_step(s, bandit_batch(rng), k, bandit_batch(rng))
        assert int(s2.step) == i + 1
        assert not leaves_equal(s.critic_params, s2.critic_params)
        assert not leaves_equal(s.critic_g_params, s2.critic_g_params)
        assert leaves_equal(s.actor_params, s2.actor_params)  # the actor steps on its own
        target_step = (i + 1) % CFG.target_update_freq == 0
        assert bool(m["target_updated"]) == target_step
        for online, target in (("actor_params", "target_actor_params"),
                               ("critic_params", "target_critic_params"),
                               ("critic_g_params", "target_critic_g_params")):
            old, new = getattr(s, target), getattr(s2, target)
            if target_step:  # Polyak towards this step's updated online params
                want = jax.tree.map(lambda t, o: p * np.asarray(t) + (1 - p) * np.asarray(o),
                                    old, getattr(s2, online))
                for x, y in zip(jax.tree.leaves(new), jax.tree.leaves(want), strict=True):
                    np.testing.assert_allclose(x, y, rtol=1e-6, atol=1e-7)
                if online != "actor_params":
                    assert not leaves_equal(old, new)
            else:  # bit-identical: the masked update multiplies by exactly 1 and 0
                assert leaves_equal(old, new)
        s = s2
    # without batch_g the distance critics stay
    s3, _ = critic_step(s, bandit_batch(rng), key)
    assert leaves_equal(s.critic_g_params, s3.critic_g_params)
    s4, m = update_actor(s, bandit_batch(rng))
    assert not leaves_equal(s.actor_params, s4.actor_params)
    assert leaves_equal(s.critic_params, s4.critic_params) and int(s4.step) == int(s.step)


@pytest.mark.parametrize(("updates", "freq", "want"),
                         [(1, 2, (2, 1)), (16, 2, (1, 8)), (2, 2, (1, 1)), (1, 1, (1, 1)),
                          (4, 8, (2, 1))])
def test_schedule_keeps_the_actor_ratio(updates, freq, want):
    steps, actor = td3.schedule(updates, freq)
    assert (steps, actor) == want
    assert steps * updates == actor * freq  # one actor step per `freq` critic steps
    with pytest.raises(ValueError, match="divide"):
        td3.schedule(3, 2)


def test_learn_scans_critic_and_actor_steps():
    s = new_state()
    rng = np.random.default_rng(0)
    batches = [bandit_batch(rng) for _ in range(3)]
    table = {k: jnp.stack([b[k] for b in batches]) for k in batches[0]}

    def sample(agent, key):  # one of three fixed batches, chosen by the key
        i = jax.random.randint(key, (), 0, 3)
        return {k: v[i] for k, v in table.items()}

    learn = jax.jit(td3.learn, static_argnames=("sample", "sample_g", "critic_updates",
                                                "actor_updates"))
    s2, m = learn(s, sample, jax.random.key(0), critic_updates=3, actor_updates=0)
    assert int(s2.step) == 3 and leaves_equal(s.actor_params, s2.actor_params)
    assert leaves_equal(s.critic_g_params, s2.critic_g_params) and "actor_loss" not in m
    s3, m = learn(s2, sample, jax.random.key(1), critic_updates=0, actor_updates=2,
                  sample_g=sample)
    assert int(s3.step) == 3 and not leaves_equal(s2.actor_params, s3.actor_params)
    assert leaves_equal(s2.critic_params, s3.critic_params) and np.isfinite(m["actor_loss"])
    s4, m = learn(s, sample, jax.random.key(0), critic_updates=2, actor_updates=1,
                  sample_g=sample)
    assert not leaves_equal(s.critic_g_params, s4.critic_g_params) and "critic_g_loss" in m


def test_learns_one_step_bandit():
    """Critic fits the reward and the actor finds the best action within 300 updates."""
    s = new_state()
    test = bandit_batch(np.random.default_rng(123), 512)
    best = test["goal"] - test["obs"][:, :G]

    @jax.jit
    def outputs(s: td3.AgentState) -> tuple[jax.Array, ...]:
        a = td3.act(s, test["obs"], test["goal"], jax.random.key(0), explore=False)
        q = td3.q_value(s, test["obs"], test["goal"], test["action"])
        q_g = td3.q_value(s, test["obs"], test["goal"], test["action"], critic="g")
        return a, q, q_g, td3.distance(s, test["obs"], test["goal"])

    def evaluate(s: td3.AgentState) -> tuple[float, float]:
        a, q, q_g, _ = outputs(s)
        return (float(np.linalg.norm(np.asarray(a) - best, axis=-1).mean()),
                float(np.mean((np.asarray(q) - test["reward"]) ** 2)),
                float(np.mean((np.asarray(q_g) - test["reward"]) ** 2)))

    err0, q_mse0, q_g_mse0 = evaluate(s)
    rng = np.random.default_rng(0)
    key = jax.random.key(1)
    for i in range(300):
        key, k = jax.random.split(key)
        s, _ = train_step(s, bandit_batch(rng), bandit_batch(rng), k, i)
    err, q_mse, q_g_mse = evaluate(s)
    assert err0 > 0.3 and err < 0.15, (err0, err)
    assert q_mse < 0.2 * q_mse0 and q_mse < 0.025, (q_mse0, q_mse)
    # the distance critics fit the same rewards (on their own batches), and since the policy
    # is now near-optimal everywhere, every goal is near: Q(s, pi, g) ~ 0 <=> d ~ 0
    assert q_g_mse < 0.2 * q_g_mse0 and q_g_mse < 0.025, (q_g_mse0, q_g_mse)
    dist = np.asarray(outputs(s)[3])
    assert np.all(dist >= 0.0) and dist.mean() < 0.5, dist.mean()


def test_vmap_over_seeds_equals_separate_runs():
    keys = jax.random.split(jax.random.key(7), 2)
    singles = [td3.init(k, OBS, G, A, CFG) for k in keys]
    # init traces under vmap (shapes only, no compile: the values are JAX's threefry contract)
    shapes = jax.eval_shape(jax.vmap(lambda k: td3.init(k, OBS, G, A, CFG)), keys)
    states = jax.tree.map(lambda *x: np.stack(x), *singles)
    assert jax.tree.map(np.shape, shapes) == jax.tree.map(np.shape, states)
    vstep = jax.jit(jax.vmap(td3.critic_step, in_axes=(0, None, 0, None)))
    rng = np.random.default_rng(0)
    for t in range(3):
        batch, batch_g = bandit_batch(rng), bandit_batch(rng)
        step_keys = jax.random.split(jax.random.key(t), 2)
        states, vm = vstep(states, batch, step_keys, batch_g)
        for i in range(2):
            singles[i], m = critic_step(singles[i], batch, step_keys[i], batch_g)
            np.testing.assert_allclose(np.asarray(vm["critic_loss"])[i], m["critic_loss"],
                                       rtol=1e-5)
    for i in range(2):
        got = jax.tree.map(lambda x, i=i: np.asarray(x)[i], states)
        for x, y in zip(jax.tree.leaves(got), jax.tree.leaves(singles[i]), strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6)
    assert not np.allclose(states.actor_params["params"]["MLP_0"]["TorchDense_0"]["kernel"][0],
                           states.actor_params["params"]["MLP_0"]["TorchDense_0"]["kernel"][1])


def test_value_q_value_and_distance():
    s = new_state()
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(5, OBS)).astype(np.float32)
    goals = rng.normal(size=(5, 3, G)).astype(np.float32)

    @jax.jit
    def inference(s: td3.AgentState, obs: jax.Array, goals: jax.Array):
        return (td3.value(s, obs, goals), td3.q_value(s, obs, goals[:, 1], target=True),
                td3.distance(s, obs, goals[:, 0]))

    v, q1, d = (np.asarray(x) for x in inference(s, obs, goals))
    assert v.shape == (5, 3) and q1.shape == (5,) and d.shape == (5,)
    np.testing.assert_allclose(q1, v[:, 1], rtol=1e-6)
    for m in range(3):  # V(s, g) = min_i Q'_i(s, pi'(s, g), g) (target nets by default)
        a = np_policy(s.target_actor_params, obs, goals[:, m])
        want = np.minimum(*(np_q(s.target_critic_params, i, obs, goals[:, m], a)
                            for i in range(2)))
        np.testing.assert_allclose(v[:, m], want, rtol=1e-4, atol=1e-5)

    # distance: online actor and online g-critics, raw outputs, min over twins, clamped at 0
    a = np_policy(s.actor_params, obs, goals[:, 0])
    raw = [np_mlp(jax.tree.map(lambda p, i=i: np.asarray(p)[i], s.critic_g_params),
                  np.concatenate([obs, goals[:, 0], a], axis=-1))[:, 0] for i in range(2)]
    np.testing.assert_allclose(d, np.maximum(np.minimum(*raw), 0.0), rtol=1e-4, atol=1e-5)


def test_critic_parametrisations_round_trip():
    """DistCritic's Q(d) and DistReverseCritic's d(Q) (agent.py) invert each other."""
    cfg = td3.TD3Config()  # gamma 0.99
    d = jnp.array([-0.5, 0.0, 1.0, 7.5, 40.0, 300.0])
    q = td3.q_from_output(d, cfg)
    np.testing.assert_allclose(q, -(1 - cfg.gamma ** np.asarray(d)) / (1 - cfg.gamma),
                               rtol=1e-5, atol=1e-6)
    reverse = dataclasses.replace(cfg, dist_critic=False)
    np.testing.assert_array_equal(td3.q_from_output(q, reverse), q)
    np.testing.assert_allclose(td3.distance_from_output(q, reverse), d, rtol=1e-3, atol=1e-3)
    np.testing.assert_array_equal(td3.distance_from_output(d, cfg), d)
    # Q is clamped to >= 1 / (gamma - 1) + 1 before the log (agent.py get_dist), so the
    # distance saturates instead of going to inf / nan
    far = td3.distance_from_output(jnp.array([-100.0, -1e6]), reverse)
    np.testing.assert_allclose(far, np.log(0.01) / np.log(0.99), rtol=1e-5)
    with_offset = dataclasses.replace(cfg, q_offset=True)
    np.testing.assert_array_equal(td3.distance_from_output(d, with_offset), d + 1.0)


def test_actor_input_is_obs_and_relative_goal():
    """agent.py ``_process_inputs_actor``: raw inputs (no normaliser), goal relative to obs[:g]."""
    rng = np.random.default_rng(0)
    obs = rng.normal(3.0, 2.0, size=(4, OBS)).astype(np.float32)
    goal = rng.normal(-1.0, 0.5, size=(4, G)).astype(np.float32)
    raw = td3.actor_input(new_state(), obs, goal)
    np.testing.assert_allclose(raw, np.concatenate([obs, goal - obs[:, :G]], -1))
