"""DHRL pieces: the high level's box, subgoal testing, and one jitted episode on the point mass."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import envs, planner, replay, train
from flrjax.agents import gc_td3
from flrjax.algos import dhrl

TINY = train.TrainConfig(env="point4leg", algo="dhrl", seeds=1, num_envs=2, steps=200,
                         episodes_per_chunk=1, batch_size=32, hidden=16, buffer_episodes=20,
                         initial_episodes=2, graph_start_steps=400, graph_every_steps=400,
                         max_landmarks=8, landmark_sample=64, eval_episodes=2)


def test_high_level_proposes_subgoals_over_the_free_box():
    env = envs.make("point4leg")  # the U-maze: free space [-4, 20]^2 (AntMaze.sh: 12 and 8)
    high = dhrl.high_config(gc_td3.TD3Config(), env.maze.bounds)
    assert high.action_max == (12.0, 12.0) and high.action_offset == (8.0, 8.0)
    assert high.noise_eps * 12.0 == pytest.approx(2.0) and high.random_eps == 0.0
    room = dhrl.high_config(gc_td3.TD3Config(), envs.make("point3leg").maze.bounds)
    assert room.action_max == (12.0, 4.0) and room.action_offset == (8.0, 0.0)
    state = gc_td3.init(jax.random.key(0), env.observation_size, 2, 2,
                        dataclasses.replace(high, hidden_sizes=(8,)))
    obs = jnp.zeros((500, env.observation_size))
    sg = gc_td3.act(state, obs, obs[:, :2], jax.random.key(1), explore=True)
    assert np.all((np.asarray(sg) >= -4.0) & (np.asarray(sg) <= 20.0))
    assert np.asarray(sg).std(0).min() > 1.0  # the noise spreads them


def _high_buffer(n_eps: int = 3, horizon: int = 4):
    """Episodes whose achieved goal at high step i is (10 * episode + i, 0) and whose proposed
    subgoal at step i is 0.5 beyond the next achieved goal in x (a hit) except at odd i (a
    miss by 3)."""
    g = jax.ShapeDtypeStruct((2,), jnp.float32)
    buf = replay.init(n_eps, horizon, n_eps, {"obs": jax.ShapeDtypeStruct((3,), jnp.float32),
                                              "achieved_goal": g}, {"action": g, "goal": g})
    ep, t = np.meshgrid(np.arange(n_eps), np.arange(horizon + 1), indexing="ij")
    ag = np.stack([10.0 * ep + t, np.zeros_like(t, float)], -1).astype(np.float32)
    miss = np.where(np.arange(horizon) % 2 == 1, 3.0, 0.5)
    action = ag[:, 1:] + np.stack([miss + 0 * ep[:, :horizon], 0 * ep[:, :horizon]], -1)
    return replay.insert_episodes(buf, {
        "obs": np.concatenate([ag, np.zeros((n_eps, horizon + 1, 1))], -1).astype(np.float32),
        "achieved_goal": ag, "action": action.astype(np.float32),
        "goal": np.full((n_eps, horizon, 2), 99.0, np.float32)})


def test_high_batch_is_subgoal_testing_as_defined():
    cfg = train.dhrl_config(dataclasses.replace(TINY, batch_size=50))
    buf = _high_buffer()
    euclid = lambda o, g: jnp.linalg.norm(o[:, :2] - g, axis=-1)  # noqa: E731
    no_graph = planner.empty_graph(4, 3, 2)
    b = jax.jit(dhrl.high_batch, static_argnums=(1, 4))(buf, euclid, no_graph,
                                                         jax.random.key(0), cfg)
    b = jax.tree.map(np.asarray, b)
    n_test = round(cfg.subgoal_test_p * 50)
    assert n_test == 10
    # every goal relabelled to a future achieved goal of the same episode, 1..15 high steps on
    ep = b["slot"]
    assert np.all(b["goal"][:, 0] >= 10 * ep + b["t"] + 1) and np.all(b["goal"][:, 1] == 0)
    # non-test samples: the subgoal is the next achieved goal (hindsight action)
    np.testing.assert_array_equal(b["action"][n_test:], b["next_achieved_goal"][n_test:])
    hit = np.linalg.norm(b["next_achieved_goal"] - b["goal"], axis=-1) <= cfg.delta
    want = np.where(hit, 0.0, -1.0)
    # test samples keep their subgoal; missed by more than 1 -> -1.3
    missed = b["t"] % 2 == 1
    want[:n_test] = np.where(missed[:n_test], -1.3, want[:n_test])
    np.testing.assert_allclose(b["action"][:n_test, 0],
                               b["next_achieved_goal"][:n_test, 0] + np.where(
                                   missed[:n_test], 3.0, 0.5))
    np.testing.assert_allclose(b["reward"], want)
    assert missed[:n_test].any() and (~missed[:n_test]).any()
    # with one landmark at (-200, 0), every tested subgoal is > 3 * cutoff away -> -5
    lm = planner.Landmarks(index=jnp.zeros(4, jnp.int32),
                           state=jnp.zeros((4, 3)).at[:, 0].set(-200.0),
                           goal=jnp.zeros((4, 2)), mask=jnp.array([True, False, False, False]))
    far = dataclasses.replace(no_graph, landmarks=lm)
    b2 = jax.tree.map(np.asarray, dhrl.high_batch(buf, euclid, far, jax.random.key(0), cfg))
    want[:n_test] = -cfg.gradual_penalty
    np.testing.assert_allclose(b2["reward"], want)


def test_episodes_plan_on_the_graph_once_it_is_built():
    """Round 0 is random (random subgoals straight to the low level); round 2 starts with a
    graph built from the replay, and the low level's stored goals are then waypoints."""
    init, chunk, evaluate = train.build(TINY)
    carry = init(jax.random.split(jax.random.key(0), 1))
    acfg = train.dhrl_config(TINY)
    assert (acfg.graph_start_round, acfg.graph_every, acfg.subgoal_freq) == (2, 2, 10)
    per_round = []
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
        per_round.append(jax.tree.map(lambda x: float(np.asarray(x).mean()), m))
        if i == 0:  # random phase: a random subgoal per period, chased directly
            goals = np.asarray(carry.low_buffer.transitions["goal"][0, :2])  # [E, T, 2]
            periods = goals.reshape(2, 10, 10, 2)
            assert np.all(periods == periods[:, :, :1])
            assert np.all((goals >= -4) & (goals <= 20))
            assert per_round[0]["critic_loss"] == 0.0  # no updates during the random rollouts
    assert per_round[0]["graph_nodes"] == 0 and per_round[1]["graph_nodes"] == 0
    assert 1 <= per_round[2]["graph_nodes"] <= 8 and per_round[1]["critic_loss"] > 0
    g = jax.tree.map(lambda x: np.asarray(x)[0], carry.graph)
    assert g.landmarks.mask.sum() == per_round[2]["graph_nodes"]
    # landmarks are (observation, achieved goal) pairs of the first two rounds' replay
    stored = np.asarray(carry.low_buffer.states["achieved_goal"][0, :4]).reshape(-1, 2)
    for lm_goal, lm_state in zip(g.landmarks.goal[g.landmarks.mask],
                                 g.landmarks.state[g.landmarks.mask], strict=True):
        assert np.any(np.all(stored == lm_goal, axis=-1))
        np.testing.assert_array_equal(lm_state[:2], lm_goal)  # the point's obs leads with xy
    ev = jax.tree.map(np.asarray, evaluate(carry, jax.random.split(jax.random.key(1), 1)))
    assert set(train.metric_fields("dhrl")) >= set(ev) and np.isfinite(ev["success_rate"]).all()
    assert carry.low_buffer.count[0] == 6 and carry.high_buffer.count[0] == 6
