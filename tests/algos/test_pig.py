"""PIG on the point mass: planned waypoints stored for the imitation, and one jitted run."""


import jax
import jax.numpy as jnp
import numpy as np

from flrjax import config, runner, validation
from flrjax.agents import gc_td3
from flrjax.algos import pig
from tests.agents.gc_td3.common import A, G, bandit_batch, new_state, np_policy

TINY = config.make(dict(env="point4leg", algo="flr_pig", seeds=1, num_envs=2, steps=200,
                          episodes_per_chunk=1, batch_size=32, hidden=16, buffer_episodes=20,
                          initial_episodes=2, graph_start_steps=200, graph_every_steps=200,
                          max_landmarks=8, landmark_sample=64, eval_episodes=2,
                          flr_candidates=4))


def test_plans_are_stored_for_the_imitation_once_the_graph_exists():
    init, chunk, evaluate = runner.build(TINY)
    acfg = config.algo_config(TINY)
    assert acfg.imitation_weight == pig.PIGConfig.imitation_weight  # the reference's
    assert acfg.flr is not None and acfg.path_len == 10
    carry = init(jax.random.split(jax.random.key(0), 1))
    metrics = []
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
        metrics.append(jax.tree.map(lambda x: float(np.asarray(x).mean()), m))
    assert metrics[0]["stats/graph_nodes"] == 0 and metrics[0]["stats/planned_steps"] == 0
    assert metrics[0]["low/critic_loss"] == 0  # the random round does not learn
    assert metrics[2]["stats/graph_nodes"] >= 1 and np.isfinite(metrics[2]["low/imitation"])
    assert np.isnan(metrics[0]["stats/dist_rank_corr"])  # no rebuild to judge
    pairs = metrics[2]["stats/graph_nodes"] >= 2  # else no pair to rank
    assert -1 <= metrics[2]["stats/dist_rank_corr"] <= 1 or not pairs
    assert metrics[2]["stats/path_to_goal"] in (0.0, 1.0)
    tr = jax.tree.map(lambda x: np.asarray(x)[0], carry.buffer.transitions)
    graph = jax.tree.map(lambda x: np.asarray(x)[0], carry.graph)
    landmarks = graph.landmarks.goal[graph.landmarks.mask]
    mask, goals = tr["imitation_mask"][:6], tr["imitation_goal"][:6]  # [episode, T, L]
    assert not mask[:2].any()  # round 0: random, and no graph yet
    # a stored plan is a prefix of waypoints, each a landmark of the graph it was planned on
    # (round 2's graph; rounds 1 and 2 each built one: compare only round 2's episodes)
    assert np.all(mask[..., 1:] <= mask[..., :-1])
    for wp in goals[4:6][mask[4:6]]:
        assert np.any(np.all(np.isclose(landmarks, wp), axis=-1))
    # the last learning round's imitation loss sets the next round's skipping
    assert float(carry.ref_loss[0]) == metrics[2]["low/imitation"] > 0
    assert metrics[0]["stats/skip_prob"] == 0  # no imitation loss before the first round
    np.testing.assert_allclose(metrics[2]["stats/skip_prob"], float(pig.skip_prob(
        jnp.float32(metrics[1]["low/imitation"]), acfg)), rtol=1e-6)
    ev = jax.tree.map(np.asarray, evaluate(carry, jax.random.split(jax.random.key(1), 1)))
    assert np.isfinite(ev["eval/final_goal_distance"]).all() and ev["eval/path_length"] >= 0
    assert 0 <= ev["eval/on_target_frac"] <= 1 and 0 <= ev["eval/no_plan_success_rate"] <= 1
    assert np.isfinite(ev["eval/no_plan_goal_distance"])


def _reference_skips(rng, p, n):
    """Planner.__call__ with ``jump``: the index reached along a series of n waypoints + the
    goal (path_len = n + 1), hopping while a Bernoulli(p) draw succeeds."""
    k = 0
    while k < n and rng.binomial(1, p):
        k += 1
    return k


def test_subgoal_skipping_matches_the_reference_loop():
    cfg = config.algo_config(TINY)
    assert float(pig.skip_prob(jnp.float32(0.0), cfg)) == 0.0  # no imitation loss yet
    assert float(pig.skip_prob(jnp.float32(2 * cfg.jump_temp), cfg)) == 0.5
    assert float(pig.skip_prob(jnp.float32(cfg.jump_temp / 10), cfg)) == 1.0
    e, big_l = 20000, 5
    waypoints = jnp.broadcast_to(jnp.arange(big_l, dtype=jnp.float32)[None, :, None],
                                 (e, big_l, 2))
    goal = jnp.full((e, 2), -1.0)
    rng = np.random.default_rng(0)
    for n in (0, 3, big_l):
        length = jnp.full((e,), n, jnp.int32)
        for p in (0.0, 0.5, 1.0):
            got = np.asarray(pig.skip_target(jax.random.key(n), waypoints, length, goal,
                                             jnp.float32(p)))[:, 0]
            index = np.where(got < 0, n, got).astype(int)  # the goal is element n
            want = [_reference_skips(rng, p, n) for _ in range(e)]
            np.testing.assert_allclose(np.bincount(index, minlength=n + 1) / e,
                                       np.bincount(want, minlength=n + 1) / e, atol=0.015,
                                       err_msg=f"n={n} p={p}")


def test_jump_temp_sweeps_in_one_run_and_zero_turns_skipping_off():
    """``--pig-jump-temp 0,1000``: two runs in one vmapped chunk, one never skipping, the other
    skipping every hop once there is an imitation loss (1000 / loss > 1), in training and in
    evaluation, where it then heads for the goal as the policy alone does."""
    cfg = TINY.replace(algo="pig", pig_jump_temp=(0.0, 1000.0))
    validation.validate(cfg)
    assert [config.algo_config(cfg, p).jump_temp
            for p in config.sweep_points(cfg)] == [0.0, 1000.0]
    init, chunk, evaluate = runner.build(cfg)
    carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
    for i in range(4):
        carry, m = chunk(carry, jnp.int32(i))
    assert np.all(np.asarray(carry.ref_loss) > 0)
    assert np.asarray(m["stats/skip_prob"]).reshape(2, -1)[:, -1].tolist() == [0.0, 1.0]
    ev = jax.tree.map(np.asarray, evaluate(carry, jax.random.split(jax.random.PRNGKey(1), 2)))
    np.testing.assert_allclose(ev["eval/final_goal_distance"][1],
                               ev["eval/no_plan_goal_distance"][1], rtol=1e-5)
    assert ev["eval/on_target_frac"][1] == 0  # never aims at a waypoint it stands on


def test_imitation_term_of_the_actor_loss():
    """weight * masked mean over (planned subgoal, action dim) of (pi(s, g) - pi(s, sg))^2,
    with the gradient through pi(s, g) only."""
    s = new_state()
    extra = pig.imitation_loss(0.5)
    rng = np.random.default_rng(0)
    batch = bandit_batch(rng, 16)
    sg = rng.uniform(-0.5, 0.5, (16, 3, G)).astype(np.float32)
    mask = rng.uniform(size=(16, 3)) < 0.5
    plain, _ = gc_td3.actor_loss(s.actor.params, s, batch)
    loss, m = gc_td3.actor_loss(s.actor.params, s, {**batch, "imitation_goal": sg,
                                                    "imitation_mask": mask}, extra)
    pi = np_policy(s.actor.params, batch["obs"], batch["goal"])
    err = [(pi - np_policy(s.actor.params, batch["obs"], sg[:, i])) ** 2 for i in range(3)]
    err = np.stack(err, 1)  # [B, L, A]
    want = (err * mask[..., None]).sum() / (mask.sum() * A)
    np.testing.assert_allclose(float(m["imitation"]), want, rtol=1e-4)
    np.testing.assert_allclose(float(loss - plain), 0.5 * want, rtol=1e-4)
    # the teacher is a constant: with every subgoal equal to the goal the term and its
    # gradient vanish (a gradient through pi(s, sg) would not cancel then either way)
    same = np.repeat(batch["goal"][:, None], 3, 1)
    grad = jax.grad(lambda p: gc_td3.actor_loss(p, s, {**batch, "imitation_goal": same,
                                                        "imitation_mask": mask}, extra)[0])(
        s.actor.params)
    grad0 = jax.grad(lambda p: gc_td3.actor_loss(p, s, batch)[0])(s.actor.params)
    for x, y in zip(jax.tree.leaves(grad), jax.tree.leaves(grad0), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-7)
