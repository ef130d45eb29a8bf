"""HIGL pieces: landmark choice on a hand-made graph, the manager's landmark loss, the
adjacency loss, and one jitted run on the point mass."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import config, planner, runner
from flrjax.algos import higl

TINY = config.make(dict(env="point4leg", algo="higl", seeds=1, num_envs=2, steps=200,
                          episodes_per_chunk=1, batch_size=32, hidden=16, buffer_episodes=20,
                          initial_episodes=2, graph_start_steps=200, graph_every_steps=200,
                          landmark_sample=64, eval_episodes=2))


def euclid(o, g):
    return jnp.linalg.norm(o[:, :2] - g, axis=-1)


def test_pseudo_landmark_heads_for_the_next_landmark_on_the_shortest_path():
    cfg = dataclasses.replace(config.algo_config(TINY), goal_thr=3.0)
    # landmarks along a U: (0,0) -> (8,0) -> (8,8) -> (0,8); edges only between neighbours
    # (cutoff 9), so from (0,-1) to the goal (0,9) the path goes round, not across
    pts = jnp.array([[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]])
    k = 40
    goal_xy = jnp.zeros((k, 2)).at[:4].set(pts)
    lm = planner.Landmarks(index=jnp.arange(k), state=jnp.zeros((k, 4)).at[:, :2].set(goal_xy),
                           goal=goal_xy, mask=jnp.arange(k) < 4)
    pd = planner.pairwise_distance(euclid, lm.state, lm.goal)
    pd = jnp.where(jnp.abs(pd - 8.0) < 1e-4, pd, jnp.where(pd < 1e-6, 0.0, 1e3))
    graph = planner.graph_from_distances(lm, pd, cutoff=9.0)
    cfg = dataclasses.replace(cfg, cutoff=9.0)
    obs = jnp.array([[0.0, -1.0, 0.0, 0.0], [9.0, -1.0, 0.0, 0.0], [0.0, 7.0, 0.0, 0.0]])
    ag = obs[:, :2]
    goal = jnp.array([[0.0, 9.0], [0.0, 9.0], [0.0, 9.0]])
    pl = np.asarray(higl.pseudo_landmarks(euclid, graph, obs, ag, goal, cfg))
    # row 0: the entry landmark is (0, 0), 1 away (then (0, 8) is 8 further: 10 in all);
    # the pseudo-landmark is 2 along that direction
    np.testing.assert_allclose(pl[0], [0.0, 1.0], atol=1e-5)
    # row 1: from (9, -1) only (8, 0) is within the cutoff: the path goes round the U through
    # it, so the pseudo-landmark points at (8, 0)
    want = np.array([9.0, -1.0]) + 2.0 * np.array([-1.0, 1.0]) / np.sqrt(2.0)
    np.testing.assert_allclose(pl[1], want, atol=1e-5)
    # row 2: the goal is 2 < goal_thr away: head straight for it
    np.testing.assert_allclose(pl[2], [0.0, 9.0], atol=1e-5)
    # no landmark at all: the achieved goal itself (the loss is then HRAC's adjacency term)
    empty = planner.empty_graph(k, 4, 2)
    far = jnp.array([[0.0, 30.0]] * 3)
    np.testing.assert_allclose(higl.pseudo_landmarks(euclid, empty, obs, ag, far, cfg), ag)


def test_landmark_and_adjacency_losses_as_defined():
    cfg = config.algo_config(TINY)
    anet = higl.init(jax.random.key(0), config.make_env(TINY), cfg).aux.anet
    rng = np.random.default_rng(0)
    ag = rng.uniform(-4, 20, (16, 2)).astype(np.float32)
    pl = rng.uniform(-4, 20, (16, 2)).astype(np.float32)
    pi = rng.uniform(-12, 12, (16, 2)).astype(np.float32)
    emb = lambda x: np.asarray(higl.ANET.apply(anet, x))  # noqa: E731
    gap = np.linalg.norm(emb(pl) - emb(ag + pi), axis=-1)
    want = 20.0 * np.maximum(gap - 1.1, 0.0).mean()
    got, _ = higl.landmark_loss(anet, cfg)(None, None, jnp.asarray(pi),
                                           {"pseudo_landmark": pl, "achieved_goal": ag})
    np.testing.assert_allclose(float(got), want, rtol=1e-4)
    d_near = np.linalg.norm(emb(ag) - emb(pl), axis=-1)
    d_far = np.linalg.norm(emb(pl) - emb(ag + pi), axis=-1)
    want = np.maximum(d_near - 1.0, 0).mean() + np.maximum(1.2 - d_far, 0).mean()
    got = higl.adjacency_loss(anet, (ag, pl), (pl, ag + pi))
    np.testing.assert_allclose(float(got), want, rtol=1e-4)


def test_higl_runs_and_builds_coverage_and_novelty_landmarks():
    init, chunk, evaluate = runner.build(TINY)
    carry = init(jax.random.split(jax.random.key(0), 1))
    acfg = config.algo_config(TINY)
    assert acfg.subgoal_freq == 5 and acfg.low_hp.gamma == 0.95
    assert acfg.high.action_max == (12.0, 12.0) and acfg.high.action_offset == (0, 0)
    ms = []
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
        ms.append(jax.tree.map(lambda x: float(np.asarray(x).mean()), m))
    assert ms[0]["low/critic_loss"] == 0 and ms[0]["stats/graph_nodes"] == 0
    assert ms[2]["stats/graph_nodes"] == 40 and ms[2]["aux/adjacency_loss"] >= 0
    assert np.isnan(ms[0]["stats/wall_edge_frac"])  # no rebuild to judge
    assert -1 <= ms[2]["stats/dist_rank_corr"] <= 1 and 0 <= ms[2]["stats/wall_edge_frac"] <= 1
    assert np.isfinite([m["stats/subgoal_progress"] for m in ms]).all()
    assert np.isfinite([ms[2][k] for k in ("low/critic_loss", "high/critic_loss",
                                           "aux/rnd_loss", "high/landmark_loss")]).all()
    # the manager's stored subgoals are relative and inside the box; its reward is
    # -0.1 per step away from the final goal, summed over the 5 steps
    hb = jax.tree.map(lambda x: np.asarray(x)[0], carry.high_buffer.transitions)
    assert np.all(np.abs(hb["action"][:6]) <= 12.0 + 1e-5)
    assert np.all((hb["reward"][:6] <= 0) & (hb["reward"][:6] >= -0.5 - 1e-6))
    # each manager transition keeps its period's low-level observations and actions, as the
    # low-level replay holds them (for the off-policy correction)
    lb = jax.tree.map(lambda x: np.asarray(x)[0], carry.low_buffer)
    for slot in (0, 3, 5):
        for p in (0, 7):
            np.testing.assert_array_equal(hb["low_obs"][slot, p],
                                          lb.states["obs"][slot, 5 * p:5 * p + 5])
            np.testing.assert_array_equal(hb["low_action"][slot, p],
                                          lb.transitions["action"][slot, 5 * p:5 * p + 5])
    ev = jax.tree.map(np.asarray, evaluate(carry, jax.random.split(jax.random.key(1), 1)))
    assert np.isfinite(ev["eval/final_goal_distance"]).all()


def test_off_policy_correction_picks_the_subgoal_that_explains_the_actions():
    """Actions recorded by the current controller towards a known absolute target: of the
    candidates, the one closest to that target's displacement wins, by the HIRO score."""
    from flrjax.agents import gc_td3

    cfg = config.algo_config(TINY)
    carry = higl.init(jax.random.key(0), config.make_env(TINY), cfg)
    low = carry.low
    rng = np.random.default_rng(0)
    b, c = 6, cfg.subgoal_freq
    ag0 = rng.uniform(0, 8, (b, 2)).astype(np.float32)
    true_sg = rng.uniform(-6, 6, (b, 2)).astype(np.float32)
    obs = rng.normal(size=(b, c, 4)).astype(np.float32)
    actions = gc_td3.policy(low, low.actor.params, obs, np.repeat((ag0 + true_sg)[:, None], c, 1))
    batch = {"achieved_goal": ag0, "next_achieved_goal": ag0 + true_sg,  # diff == true_sg
             "action": rng.uniform(-12, 12, (b, 2)).astype(np.float32),
             "low_obs": obs, "low_action": np.asarray(actions)}
    got = np.asarray(higl.corrected_subgoals(low, batch, jax.random.key(1), cfg))
    np.testing.assert_allclose(got, true_sg, atol=1e-5)  # the displacement explains them
    # with the stored subgoal as the true one, it is kept (index 0 wins ties)
    batch["action"] = true_sg
    batch["next_achieved_goal"] = ag0 + 3.0
    got = np.asarray(higl.corrected_subgoals(low, batch, jax.random.key(1), cfg))
    np.testing.assert_allclose(got, true_sg, atol=1e-5)


def test_higl_graph_defaults_are_its_own_and_fill_unset_sweep_points():
    """HIGL's subgoal period (10 on the ant, 5 on the point mass), edge cutoff (38) and
    manager noise (1) are its options class's defaults: a flag given wins, and a --sweep
    point that leaves one unset takes HIGL's, not DHRL's."""
    for env, period in (("ant3leg", 10), ("point4leg", 5)):
        acfg = config.algo_config(config.make(dict(env=env, algo="higl")))
        assert (acfg.subgoal_freq, acfg.cutoff) == (period, 38.0)
        assert config.algo_config(config.make(dict(env=env, algo="dhrl"))).cutoff != 38.0
    given = config.algo_config(config.make(dict(env="ant3leg", algo="higl", cutoff=20.0,
                                                subgoal_freq=20)))
    assert (given.subgoal_freq, given.cutoff) == (20, 20.0)
    swept = config.make(dict(env="ant3leg", algo="higl",
                             sweep=((("cutoff", 20.0),), (("subgoal_noise_eps", 1.5),))))
    assert config.sweep_points(swept) == [{"cutoff": 20.0, "subgoal_noise_eps": 1.0},
                                          {"cutoff": 38.0, "subgoal_noise_eps": 1.5}]
