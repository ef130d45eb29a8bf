"""The low level's batches and rewards: eq. (5) against brute force on the target critic, its
bf16 values against float32, n-step sums against the stored trajectory."""

import dataclasses

import jax
import numpy as np
import pytest

from flrjax import config, replay, rewards
from flrjax.agents import gc_td3
from flrjax.algos import flr, hierarchy, low_batches
from flrjax.metric_names import scoped
from tests.tiny import DHRL as TINY


@pytest.mark.parametrize("next_subgoal, value_chunk", [("sample", None), ("goal", None),
                                                       ("sample", 5)])
def test_low_reward_with_flr_is_eq5_on_the_target_critic(next_subgoal, value_chunk):
    """Also when V is evaluated on the reaching transitions only, 5 at a time (8 reach)."""
    cfg = config.algo_config(TINY)
    cfg = dataclasses.replace(cfg, flr=flr.FLRConfig(alpha=0.01, eps=2.0, num_candidates=5,
                                                      next_subgoal=next_subgoal,
                                                      value_chunk=value_chunk))
    agent = gc_td3.init(jax.random.key(0), 4, 2, 2, cfg.low, cfg.low_hp)
    # make the target networks differ from the online ones, so the test tells them apart
    agent = agent.replace(critic=agent.critic.replace(
        target_params=jax.tree.map(lambda x: 1.5 * x, agent.critic.target_params)))
    rng = np.random.default_rng(0)
    b = 12
    goal = rng.uniform(0, 16, (b, 2)).astype(np.float32)
    reached = np.arange(b) % 3 != 0
    next_ag = np.where(reached[:, None], goal + 0.1, goal + 3.0).astype(np.float32)
    batch = {"goal": goal, "next_achieved_goal": next_ag,
             "next_obs": np.concatenate([next_ag, rng.normal(size=(b, 2))], -1).astype(
                 np.float32),
             "final_goal": rng.uniform(0, 16, (b, 2)).astype(np.float32),
             "next_fallen": np.arange(b) % 4 == 1}
    key = jax.random.key(3)
    reward, stats = low_batches.low_reward(agent, batch, key, cfg)
    reward = np.asarray(reward)
    if next_subgoal == "goal":
        cands, eps = batch["final_goal"][:, None], 0.0
    else:  # the same draw as inside (same key), clipped to the subgoal box [-4, 20]^2
        cands = np.asarray(rewards.sample_next_subgoals(key, goal, eps=2.0, num=5, low=-4.0,
                                                        high=20.0))
        eps = 2.0
    v_min = -1.0 / (1.0 - cfg.low_hp.gamma)
    for i in range(b):
        if not reached[i]:
            assert reward[i] == -1.0
            continue
        best = -np.inf
        for c in cands[i]:
            if np.linalg.norm(c - goal[i]) >= eps - 1e-4:
                v = float(gc_td3.q_value(agent, batch["next_obs"][i], c, target=True))
                best = max(best, min(max(v, v_min), 0.0))
        assert np.isfinite(best)
        np.testing.assert_allclose(reward[i], 0.01 * best, rtol=1e-4, atol=1e-6)
        assert reward[i] >= -1.0  # eq. (4) with alpha = 1 - gamma
    up = reached & ~batch["next_fallen"]
    assert float(stats["reach_up_n"]) == up.sum()
    np.testing.assert_allclose(float(stats["reach_up_reward"]), reward[up].sum(), rtol=1e-5)
    np.testing.assert_allclose(float(stats["reach_fall_reward"]),
                               reward[reached & batch["next_fallen"]].sum(), rtol=1e-5)
    assert float(stats["sampled_n"]) == b
    gap = low_batches.reward_gap(scoped("stats", stats))
    np.testing.assert_allclose(float(gap["stats/reach_frac"]), reached.mean(), rtol=1e-6)


def test_flr_rewards_with_bf16_values_stay_within_the_candidates_own_noise():
    """eq. 5 with bf16 matrix operands (the trainer's default) against float32: on 3x256
    critics whose values lie near the ant's (V ~ -26), every reward is within 0.5% of the
    float32 one (stated tolerance: 5e-3 of |reward|, plus 1e-5), and the mean change is under
    half of what drawing the 16 candidates anew does to the float32 reward itself; by XLA and
    by the fused kernel."""
    cfg = config.algo_config(TINY)
    low = dataclasses.replace(cfg.low, hidden_sizes=(256, 256, 256))
    obs = 30
    agent = gc_td3.init(jax.random.key(0), obs, 2, 2, low)

    def to_ant_scale(path, x):  # the critics' last layer: distances d ~ 30 +- 20 steps
        if "TorchDense_3" not in jax.tree_util.keystr(path):
            return x
        return 20.0 * x + (30.0 if "bias" in jax.tree_util.keystr(path) else 0.0)

    agent = agent.replace(critic=agent.critic.replace(
        target_params=jax.tree_util.tree_map_with_path(to_ant_scale,
                                                       agent.critic.target_params)))
    rng = np.random.default_rng(0)
    b = 512
    goal = rng.uniform(-4, 20, (b, 2)).astype(np.float32)
    batch = {"goal": goal, "next_achieved_goal": goal + 0.1,
             "next_obs": np.concatenate([goal + 0.1, rng.normal(size=(b, obs - 2))], -1)
             .astype(np.float32),
             "final_goal": rng.uniform(0, 16, (b, 2)).astype(np.float32),
             "next_fallen": np.zeros(b, bool)}

    def reward(dtype: str, key: jax.Array, kernel: str = "xla", chunk: int | None = 128
               ) -> np.ndarray:
        c = dataclasses.replace(cfg, low=low, flr=flr.FLRConfig(
            value_dtype=dtype, value_kernel=kernel, value_chunk=chunk))
        return np.asarray(jax.jit(lambda k: low_batches.low_reward(agent, batch, k, c)[0])(key))

    f32, bf16 = reward("float32", jax.random.key(1)), reward("bfloat16", jax.random.key(1))
    redrawn = reward("float32", jax.random.key(2))
    assert -0.5 < f32.mean() < -0.1  # alpha * V with V ~ -26, as on the ant
    np.testing.assert_allclose(bf16, f32, rtol=5e-3, atol=1e-5)
    assert np.abs(bf16 - f32).mean() < 0.5 * np.abs(redrawn - f32).mean()
    # the GPU's fused kernel (gc_td3.fused_value; Pallas's interpreter here): the same bound
    fused = reward("bfloat16", jax.random.key(1), "fused")
    np.testing.assert_allclose(fused, f32, rtol=5e-3, atol=1e-5)
    assert np.abs(fused - f32).mean() < 0.5 * np.abs(redrawn - f32).mean()
    # as the GPU runs it: the whole batch, the reaching transitions first (all of them here)
    np.testing.assert_allclose(reward("bfloat16", jax.random.key(1), "fused", None), fused,
                               rtol=1e-6)


@pytest.mark.parametrize("algo", ["dhrl", "flr_dhrl"])
def test_n_step_batch_sums_the_stored_steps_rewards(algo):
    """--n-step 3: the main critics' batch sums gamma**i times eq. (1)'s reward of the i-th
    stored step after each sampled transition under its (relabelled) goal, fewer where the
    episode ends, and bootstraps from the state after them with gamma**steps (brute force
    over the buffer). With FLR a reaching step pays alpha max V in [-1, 0] (eq. 4) in place of
    eq. (1)'s 0: the same sums where no step reaches, lower or equal elsewhere."""
    cfg = config.algo_config(TINY.replace(algo=algo, n_step=3))
    assert cfg.low.n_step == 3 and cfg.high.n_step == 1
    env = config.make_env(TINY)
    horizon = 6
    buffer = replay.init(4, horizon, 2, *hierarchy.low_spec(env))
    rng = np.random.default_rng(0)
    ag = np.round(rng.uniform(0, 3, (4, horizon + 1, 2))).astype(np.float32)  # some repeat
    obs = np.concatenate([ag, rng.normal(size=(4, horizon + 1, env.observation_size - 2))],
                         -1).astype(np.float32)
    buffer = replay.insert_episodes(buffer, {
        "obs": obs, "achieved_goal": ag, "torso_z": np.ones((4, horizon + 1), np.float32),
        "fallen": np.zeros((4, horizon + 1), bool),
        "action": rng.uniform(-1, 1, (4, horizon, 2)).astype(np.float32),
        "goal": rng.uniform(0, 3, (4, horizon, 2)).astype(np.float32),
        "final_goal": np.full((4, horizon, 2), 8.0, np.float32)})
    agent = gc_td3.init(jax.random.key(0), env.observation_size, 2, 2, cfg.low, cfg.low_hp)
    key = jax.random.key(1)
    batch = replay.sample(buffer, key, 64, future_p=0.5, future_step=4)
    batch["reward"], _ = low_batches.low_reward(agent, batch, key, cfg)
    got = jax.tree.map(np.asarray, low_batches.n_step_batch(buffer, agent, batch, key, cfg))
    gamma = float(cfg.low_hp.gamma)
    slot, t, goal = (np.asarray(batch[k]) for k in ("slot", "t", "goal"))
    sparse = np.zeros(64)
    for b in range(64):
        steps = min(3, horizon - t[b])
        reached = [np.linalg.norm(ag[slot[b], t[b] + i + 1] - goal[b]) < cfg.delta
                   for i in range(steps)]
        sparse[b] = sum(gamma ** i * (0.0 if r else -1.0) for i, r in enumerate(reached))
        np.testing.assert_allclose(got["discount"][b], gamma ** steps, rtol=1e-6)
        np.testing.assert_array_equal(got["next_obs"][b], obs[slot[b], t[b] + steps])
        if algo == "dhrl" or not any(reached):
            np.testing.assert_allclose(got["reward"][b], sparse[b], rtol=1e-5, atol=1e-6)
        else:
            floor = -sum(gamma ** i for i in range(steps))  # every step paying -1
            assert floor - 1e-5 <= got["reward"][b] <= sparse[b] + 1e-5
    assert (got["discount"] < gamma ** 2).any() and (t > horizon - 3).any()
    if algo == "flr_dhrl":
        assert (got["reward"] < sparse - 1e-6).any()  # eq. 5 paid where steps reached
