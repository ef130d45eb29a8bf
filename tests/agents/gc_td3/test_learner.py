"""Tests for flrjax.agents.gc_td3.learner: init, the update steps, the schedule, learning."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import learner, losses, networks
from tests.agents.gc_td3.common import (
    CFG,
    HP,
    OBS,
    A,
    G,
    bandit_batch,
    critic_step,
    leaves_equal,
    new_state,
    np_mlp,
    train_step,
    update_actor,
)


def test_init_shapes_and_targets_are_copies():
    s = new_state()
    assert s.step.dtype == jnp.int32 and int(s.step) == 0
    assert leaves_equal(s.actor.params, s.actor.target_params)
    assert leaves_equal(s.critic.params, s.critic.target_params)
    k = s.critic.params["params"]["MLP_0"]["TorchDense_0"]["kernel"]
    assert k.shape == (2, OBS + G + A, 64)
    assert not np.allclose(k[0], k[1])  # twin critics are initialised independently
    assert not np.allclose(k, s.critic_g.params["params"]["MLP_0"]["TorchDense_0"]["kernel"])


def test_critic_step_counts_and_polyak_targets_every_10th_step():
    s = new_state()
    rng = np.random.default_rng(0)
    key = jax.random.key(0)
    p = HP.polyak
    for i in range(21):
        key, k = jax.random.split(key)
        s2, m = critic_step(s, bandit_batch(rng), k, bandit_batch(rng))
        assert int(s2.step) == i + 1
        assert not leaves_equal(s.critic.params, s2.critic.params)
        assert not leaves_equal(s.critic_g.params, s2.critic_g.params)
        assert leaves_equal(s.actor.params, s2.actor.params)  # the actor steps on its own
        target_step = (i + 1) % CFG.target_update_freq == 0
        assert bool(m["target_updated"]) == target_step
        for net in ("actor", "critic", "critic_g"):
            old, new = getattr(s, net).target_params, getattr(s2, net).target_params
            if target_step:  # Polyak towards this step's updated online params
                want = jax.tree.map(lambda t, o: p * np.asarray(t) + (1 - p) * np.asarray(o),
                                    old, getattr(s2, net).params)
                for x, y in zip(jax.tree.leaves(new), jax.tree.leaves(want), strict=True):
                    np.testing.assert_allclose(x, y, rtol=1e-6, atol=1e-7)
                if net != "actor":
                    assert not leaves_equal(old, new)
            else:  # bit-identical: the masked update multiplies by exactly 1 and 0
                assert leaves_equal(old, new)
        s = s2
    # without batch_g the distance critics stay
    s3, _ = critic_step(s, bandit_batch(rng), key)
    assert leaves_equal(s.critic_g.params, s3.critic_g.params)
    s4, m = update_actor(s, bandit_batch(rng))
    assert not leaves_equal(s.actor.params, s4.actor.params)
    assert leaves_equal(s.critic.params, s4.critic.params) and int(s4.step) == int(s.step)


@pytest.mark.parametrize(("updates", "freq", "want"),
                         [(1, 2, (2, 1)), (16, 2, (1, 8)), (2, 2, (1, 1)), (1, 1, (1, 1)),
                          (4, 8, (2, 1))])
def test_schedule_keeps_the_actor_ratio(updates, freq, want):
    steps, actor = gc_td3.schedule(updates, freq)
    assert (steps, actor) == want
    assert steps * updates == actor * freq  # one actor step per `freq` critic steps
    with pytest.raises(ValueError, match="divide"):
        gc_td3.schedule(3, 2)


def test_learn_scans_critic_and_actor_steps():
    s = new_state()
    rng = np.random.default_rng(0)
    batches = [bandit_batch(rng) for _ in range(3)]
    table = {k: jnp.stack([b[k] for b in batches]) for k in batches[0]}

    def sample(agent, key):  # one of three fixed batches, chosen by the key
        i = jax.random.randint(key, (), 0, 3)
        return {k: v[i] for k, v in table.items()}

    learn = jax.jit(gc_td3.learn, static_argnames=("sample", "sample_g", "critic_updates",
                                                   "actor_updates"))
    s2, m = learn(s, sample, jax.random.key(0), critic_updates=3, actor_updates=0)
    assert int(s2.step) == 3 and leaves_equal(s.actor.params, s2.actor.params)
    assert leaves_equal(s.critic_g.params, s2.critic_g.params) and "actor_loss" not in m
    s3, m = learn(s2, sample, jax.random.key(1), critic_updates=0, actor_updates=2,
                  sample_g=sample)
    assert int(s3.step) == 3 and not leaves_equal(s2.actor.params, s3.actor.params)
    assert leaves_equal(s2.critic.params, s3.critic.params) and np.isfinite(m["actor_loss"])
    s4, m = learn(s, sample, jax.random.key(0), critic_updates=2, actor_updates=1,
                  sample_g=sample)
    assert not leaves_equal(s.critic_g.params, s4.critic_g.params) and "critic_g_loss" in m


def test_learns_one_step_bandit():
    """Critic fits the reward and the actor finds the best action within 300 updates."""
    s = new_state()
    test = bandit_batch(np.random.default_rng(123), 512)
    best = test["goal"] - test["obs"][:, :G]

    @jax.jit
    def outputs(s: gc_td3.AgentState) -> tuple[jax.Array, ...]:
        a = gc_td3.act(s, test["obs"], test["goal"], jax.random.key(0), explore=False)
        q = gc_td3.q_value(s, test["obs"], test["goal"], test["action"])
        q_g = gc_td3.q_value(s, test["obs"], test["goal"], test["action"],
                              distance_critics=True)
        return a, q, q_g, gc_td3.distance(s, test["obs"], test["goal"])

    def evaluate(s: gc_td3.AgentState) -> tuple[float, float]:
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
    singles = [gc_td3.init(k, OBS, G, A, CFG) for k in keys]
    # init traces under vmap (shapes only, no compile: the values are JAX's threefry contract)
    shapes = jax.eval_shape(jax.vmap(lambda k: gc_td3.init(k, OBS, G, A, CFG)), keys)
    states = jax.tree.map(lambda *x: np.stack(x), *singles)
    assert jax.tree.map(np.shape, shapes) == jax.tree.map(np.shape, states)
    vstep = jax.jit(jax.vmap(learner.critic_step, in_axes=(0, None, 0, None)))
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
    assert not np.allclose(states.actor.params["params"]["MLP_0"]["TorchDense_0"]["kernel"][0],
                           states.actor.params["params"]["MLP_0"]["TorchDense_0"]["kernel"][1])


def _bf16(s: gc_td3.AgentState) -> gc_td3.AgentState:
    """The same agent, updated with bf16 matrix operands."""
    return s.replace(config=dataclasses.replace(s.config, train_precision="bfloat16"))


def _flat(tree) -> np.ndarray:
    return np.concatenate([np.ravel(x) for x in jax.tree.leaves(tree)])


def test_bf16_updates_stay_close_to_float32_and_keep_float32_state():
    """One critic step and one actor step with bf16 operands against float32's, from the same
    state. bf16 keeps 8 significant bits (relative rounding 2^-9 ~ 0.2% per operand), so
    through 3 layers the losses and Q values move by well under 1% of their scale (~0.5 here);
    the gradients, read in Adam's first moment ((1 - b1) * grad after one step), by a few %
    (sums with cancellation). Adam's first step moves each parameter by ~lr along its
    gradient's sign, so new parameters agree wherever the signs do: nearly all of them."""
    s = new_state()
    batch = bandit_batch(np.random.default_rng(0))
    key = jax.random.key(1)
    steps = {"critic": lambda s: critic_step(s, batch, key),
             "actor": lambda s: update_actor(s, batch)}
    for net, step in steps.items():
        (f32, m32), (b16, m16) = step(s), step(_bf16(s))
        for k in m32:
            np.testing.assert_allclose(m16[k], m32[k], rtol=1e-2, atol=3e-3, err_msg=k)
        new32, new16 = getattr(f32, net), getattr(b16, net)
        assert all(x.dtype == jnp.float32 for x in jax.tree.leaves(
            (new16.params, new16.target_params, new16.opt_state[0].mu, new16.opt_state[0].nu)))
        for g32, g16 in zip(jax.tree.leaves(new32.opt_state[0].mu),
                            jax.tree.leaves(new16.opt_state[0].mu), strict=True):
            assert np.linalg.norm(g16 - g32) < 0.1 * np.linalg.norm(g32)
        lr = HP.lr_critic if net == "critic" else HP.lr_actor
        assert np.median(np.abs(_flat(new32.params) - _flat(getattr(s, net).params))) > 0.5 * lr
        assert np.mean(np.abs(_flat(new16.params) - _flat(new32.params)) < 1e-5) > 0.95


def _dots(fn, *args) -> tuple[int, int]:
    """(bf16, float32) matrix products of ``fn``'s lowered StableHLO, by operand dtype."""
    ops = [line.split("->")[0] for line in jax.jit(fn).lower(*args).as_text().splitlines()
           if "stablehlo.dot_general" in line]
    bf16 = sum("bf16" in op for op in ops)
    return bf16, len(ops) - bf16


@pytest.mark.parametrize("update", ["critic", "actor"])
def test_bf16_updates_multiply_in_bf16_forward_and_backward(update):
    """Every product of an update, its gradients' included, has bf16 operands with
    train_precision bfloat16 and none with float32. With hidden (64, 64) each update has 14
    products: forward 9 (critic: target actor, target twin, twin) or 6 (actor: actor, critic),
    the rest backward (a weight gradient per layer, an input gradient per layer but the
    data's). JAX's own transpose of the bf16 forward left those 5 or 8 in float32."""
    s, batch, key = new_state(), bandit_batch(np.random.default_rng(0)), jax.random.key(1)
    if update == "critic":
        full, args = learner.update_critic, (batch, key)

        def forward(s, batch, key):
            return losses.critic_loss(s.critic.params, s, batch,
                                      losses.critic_target(s, batch, key))
    else:
        full, args = learner.update_actor, (batch,)

        def forward(s, batch):
            return losses.actor_loss(s.actor.params, s, batch)

    bf16_32, f32_32 = _dots(full, s, *args)
    assert bf16_32 == 0 and f32_32 > 0
    n_fwd, f32_fwd = _dots(forward, _bf16(s), *args)
    assert f32_fwd == 0
    bf16_16, f32_16 = _dots(full, _bf16(s), *args)
    assert f32_16 == 0 and bf16_16 == f32_32
    layers = len(CFG.hidden_sizes) + 1
    assert bf16_16 - n_fwd >= 2 * layers - 1


def test_obs_norm_feeds_every_network_inputs_normalised_by_the_batches_learnt_from():
    """--obs-norm: the state holds running statistics of the observations of every critic
    step's batch (exact mean and std, floored at DHRL's normalizer eps), the critics and the
    actor read inputs normalised by them (checked against the NumPy forward pass); without
    the flag the state has no such leaf."""
    cfg = dataclasses.replace(CFG, obs_norm=True)
    s = gc_td3.init(jax.random.key(0), OBS, G, A, cfg, HP)
    np.testing.assert_array_equal(s.obs_stats.mean, np.zeros(OBS))
    np.testing.assert_array_equal(s.obs_stats.std, np.ones(OBS))
    raw = new_state()
    assert raw.obs_stats is None and len(jax.tree.leaves(s)) == len(
        jax.tree.leaves(raw)) + len(jax.tree.leaves(s.obs_stats))
    rng = np.random.default_rng(0)
    scale = np.array([1.0, 10.0, 100.0, 1e-4], np.float32)  # the last one constant: the floor
    batches = []
    for _ in range(3):
        b = bandit_batch(rng)
        b["obs"] = (b["obs"] * scale + np.float32(5.0)).astype(np.float32)
        batches.append(b)
    step = jax.jit(learner.critic_step)
    for i, b in enumerate(batches):
        s, m = step(s, b, jax.random.key(i))
        assert np.isfinite(m["critic_loss"])
    seen = np.concatenate([b["obs"] for b in batches]).astype(np.float64)
    mean, std = seen.mean(0), np.maximum(seen.std(0), learner.OBS_STD_MIN)
    np.testing.assert_allclose(s.obs_stats.mean, mean, rtol=1e-5)
    np.testing.assert_allclose(s.obs_stats.std, std, rtol=1e-4)
    assert std[-1] == learner.OBS_STD_MIN
    obs, goal, action = (batches[0][k] for k in ("obs", "goal", "action"))
    z, g_z = (obs - mean) / std, (goal - mean[:G]) / std[:G]
    q = np_mlp(jax.tree.map(lambda p: np.asarray(p)[0], s.critic.params),
               np.concatenate([z, g_z, action / CFG.action_max], -1))[:, 0]
    out = networks.critic_outputs(s, s.critic.params, obs, goal, action)[0]
    np.testing.assert_allclose(out, q, rtol=1e-4, atol=1e-4)
    pi = np.tanh(np_mlp(s.actor.params, np.concatenate([z, (goal - obs[:, :G]) / std[:G]], -1)))
    np.testing.assert_allclose(networks.policy(s, s.actor.params, obs, goal), pi * CFG.action_max,
                               rtol=1e-4, atol=1e-5)
