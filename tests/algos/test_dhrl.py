"""DHRL pieces: the high level's box, subgoal testing, and one jitted episode on the point mass."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import config, envs, networks, planner, replay, runner
from flrjax.agents import gc_td3
from flrjax.algos import dhrl, hierarchy, onset
from flrjax.cli import parse_args
from flrjax.envs import geodesic
from flrjax.metric_names import columns
from tests.tiny import DHRL as TINY


def test_high_level_proposes_subgoals_over_the_free_box():
    env = envs.make("point4leg")  # the U-maze: free space [-4, 20]^2 (AntMaze.sh: 12 and 8)
    high = hierarchy.high_config(gc_td3.TD3Config(), env.maze.bounds)
    hp = hierarchy.high_hparams(gc_td3.Hparams.create(), env.maze.bounds)
    assert high.action_max == (12.0, 12.0) and high.action_offset == (8.0, 8.0)
    assert hp.noise_eps * 12.0 == pytest.approx(2.0) and hp.random_eps == 0.0
    room = hierarchy.high_config(gc_td3.TD3Config(), envs.make("point3leg").maze.bounds)
    assert room.action_max == (12.0, 4.0) and room.action_offset == (8.0, 0.0)
    state = gc_td3.init(jax.random.key(0), env.observation_size, 2, 2,
                        dataclasses.replace(high, hidden_sizes=(8,)), hp)
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
    cfg = config.algo_config(dataclasses.replace(TINY, batch_size=50))
    buf = _high_buffer()
    euclid = lambda o, g: jnp.linalg.norm(o[:, :2] - g, axis=-1)  # noqa: E731
    no_graph = planner.empty_graph(4, 3, 2)
    high = gc_td3.init(jax.random.key(1), 3, 2, 2, cfg.high, cfg.high_hp)  # future_p 1
    b = jax.jit(dhrl.high_batch, static_argnums=(1, 5))(buf, euclid, no_graph, high,
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
    b2 = jax.tree.map(np.asarray, dhrl.high_batch(buf, euclid, far, high, jax.random.key(0),
                                                              cfg))
    want[:n_test] = -cfg.gradual_penalty
    np.testing.assert_allclose(b2["reward"], want)
    # distinct landmarks, (0, 0) masked out: -5 exactly where the nearest valid landmark is
    # > 3 * cutoff from the tested subgoal (brute force over the sampled subgoals)
    xy = np.array([[-5.0, 0.0], [0.0, 0.0], [-200.0, 0.0], [-8.0, 3.0]], np.float32)
    valid = np.array([True, False, True, True])
    lm = planner.Landmarks(index=jnp.arange(4), state=jnp.asarray(np.pad(xy, ((0, 0), (0, 1)))),
                           goal=jnp.asarray(xy), mask=jnp.asarray(valid))
    b3 = jax.tree.map(np.asarray, dhrl.high_batch(buf, euclid, dataclasses.replace(
        no_graph, landmarks=lm), high, jax.random.key(0), cfg))
    tested = b3["action"][:n_test]
    nearest = np.linalg.norm(tested[:, None] - xy[valid][None], axis=-1).min(1)
    far = nearest > 3 * cfg.cutoff
    assert far.any() and (~far).any()
    want[:n_test] = np.where(far, -cfg.gradual_penalty, b["reward"][:n_test])
    np.testing.assert_allclose(b3["reward"], want)


def test_episodes_plan_on_the_graph_once_it_is_built():
    """Round 0 is random (random subgoals straight to the low level); round 2 starts with a
    graph built from the replay, and the low level's stored goals are then waypoints."""
    init, chunk, evaluate = runner.build(TINY)
    carry = init(jax.random.split(jax.random.key(0), 1))
    acfg = config.algo_config(TINY)
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
            assert per_round[0]["low/critic_loss"] == 0.0  # no updates during the random rollouts
    assert per_round[0]["stats/graph_nodes"] == 0 and per_round[1]["stats/graph_nodes"] == 0
    assert 1 <= per_round[2]["stats/graph_nodes"] <= 8 and per_round[1]["low/critic_loss"] > 0
    # the graph's quality is judged on the rounds that rebuild it; the subgoals' in every round
    for name in onset.BUILD_STATS:
        assert np.isnan(per_round[1][f"stats/{name}"])
    pairs = per_round[2]["stats/graph_nodes"] >= 2  # else no pair to rank, no edge
    assert -1 <= per_round[2]["stats/dist_rank_corr"] <= 1 or not pairs
    assert 0 <= per_round[2]["stats/wall_edge_frac"] <= 1 or not pairs
    assert per_round[2]["stats/path_to_goal"] in (0.0, 1.0)
    for m in per_round:
        assert np.isfinite([m["stats/subgoal_progress"], m["stats/period_progress"]]).all()
        assert m["stats/subgoal_distance"] >= 0 and 0 <= m["stats/plan_found_frac"] <= 1
    g = jax.tree.map(lambda x: np.asarray(x)[0], carry.graph)
    assert g.landmarks.mask.sum() == per_round[2]["stats/graph_nodes"]
    # landmarks are (observation, achieved goal) pairs of the first two rounds' replay
    stored = np.asarray(carry.low_buffer.states["achieved_goal"][0, :4]).reshape(-1, 2)
    for lm_goal, lm_state in zip(g.landmarks.goal[g.landmarks.mask],
                                 g.landmarks.state[g.landmarks.mask], strict=True):
        assert np.any(np.all(stored == lm_goal, axis=-1))
        np.testing.assert_array_equal(lm_state[:2], lm_goal)  # the point's obs leads with xy
    maze = envs.make(TINY.env).maze
    gap = geodesic.distance(geodesic.table(maze), g.landmarks.goal[g.landmarks.mask], maze.goal)
    np.testing.assert_allclose(per_round[2]["stats/goal_landmark_gap"], gap.min())
    # the landmarks come from a sample of the replay: each is at least as far from the goal
    reach = geodesic.distance(geodesic.table(maze), stored, maze.goal).min()
    np.testing.assert_allclose(per_round[2]["stats/replay_goal_gap"], reach)
    assert reach <= per_round[2]["stats/sample_goal_gap"] <= gap.min()
    ev = jax.tree.map(np.asarray, evaluate(carry, jax.random.split(jax.random.key(1), 1)))
    assert set(runner.metric_fields(TINY)) >= set(columns(ev))
    assert np.isfinite(ev["eval/success_rate"]).all()
    assert carry.low_buffer.count[0] == 6 and carry.high_buffer.count[0] == 6


def test_high_buffer_is_the_trajectory_at_subgoal_boundaries():
    """The high level's episode, read back from its replay, is the low level's trajectory
    sampled every ``subgoal_freq`` steps: state ``p`` is the state at step ``p * k`` (so
    ``next_achieved_goal`` of high step ``p`` is where its subgoal period ended, the final
    state included), its action the subgoal the low level chased from step ``p * k`` on (no
    graph yet: the subgoal itself) and its goal the episode's final goal, for every env of a
    random round and of a learning round."""
    init, chunk, _ = runner.build(TINY)
    carry = init(jax.random.split(jax.random.key(0), 1))
    for i in range(2):  # round 0 random, round 1 learning; the first graph comes in round 2
        carry, _ = chunk(carry, jnp.int32(i))
    k = config.algo_config(TINY).subgoal_freq
    low, high = (jax.tree.map(lambda x: np.asarray(x)[0], b)
                 for b in (carry.low_buffer, carry.high_buffer))
    assert high.count == low.count == 4 and high.horizon * k == low.horizon
    for name in ("obs", "achieved_goal"):
        np.testing.assert_array_equal(high.states[name], low.states[name][:, ::k])
    np.testing.assert_array_equal(high.transitions["action"], low.transitions["goal"][:, ::k])
    np.testing.assert_array_equal(high.transitions["goal"],
                                  low.transitions["final_goal"][:, ::k])
    hb = jax.tree.map(lambda x: x[0], carry.high_buffer)
    b = jax.tree.map(np.asarray, replay.sample(hb, jax.random.key(2), 64, future_p=1.0,
                                               future_step=high.horizon))
    np.testing.assert_array_equal(b["next_achieved_goal"],
                                  low.states["achieved_goal"][b["slot"], (b["t"] + 1) * k])
    assert (b["t"] == high.horizon - 1).any()  # the last period ends at the final state


def test_subgoal_testing_with_bf16_distances_flags_the_same_far_subgoals():
    """Subgoal testing's far check (nearest landmark farther than 3 * cutoff) with bf16 matrix
    operands (the GPU default) against float32: on 3x256 distance critics whose nearest-
    landmark distances straddle the ant's threshold (90 steps), each distance moves by under
    1% of the threshold (the stated tolerance, 0.9 steps; measured: under 0.5), and every
    subgoal farther than that from the threshold (most of them) gets the same verdict; by XLA
    and by the fused kernel (all 300 landmarks in one call)."""
    cfg = config.algo_config(TINY)
    low = dataclasses.replace(cfg.low, hidden_sizes=(256, 256, 256))
    obs, thr = 30, 3 * planner.CUTOFF  # the ant's threshold: 90 steps
    agent = gc_td3.init(jax.random.key(0), obs, 2, 2, low)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-4, 20, (300, 2))
    lm = planner.Landmarks(
        index=jnp.arange(300), goal=jnp.asarray(xy, jnp.float32),
        state=jnp.asarray(np.concatenate([xy, rng.normal(size=(300, obs - 2))], -1),
                          jnp.float32),
        mask=jnp.asarray(rng.random(300) < 0.8))
    graph = dataclasses.replace(planner.empty_graph(300, obs, 2), landmarks=lm)
    subgoals = jnp.asarray(rng.uniform(-4, 20, (205, 2)), jnp.float32)

    def nearest(precision: str, shift: float = 0.0, kernel: str = "xla") -> np.ndarray:
        def spread(path, x):  # last layer: distances spread by tens of steps, shifted
            if "TorchDense_3" not in jax.tree_util.keystr(path):
                return x
            return 200.0 * x + (shift if "bias" in jax.tree_util.keystr(path) else 0.0)

        a = agent.replace(critic_g=agent.critic_g.replace(
            params=jax.tree_util.tree_map_with_path(spread, agent.critic_g.params)))
        dist = hierarchy.dist_fn(a, networks.dot_dtype(precision), kernel)
        rows = 300 if kernel == "fused" else planner.PAIRWISE_ROWS
        return np.asarray(jax.jit(lambda: planner.graph_to_goal_distance(
            graph, planner.pairwise_distance(dist, lm.state, subgoals, rows).T))())

    shift = thr + 1e3 - np.median(nearest("float32", 1e3))  # no distance clamped at 0
    f32, bf16 = nearest("float32", shift), nearest("bfloat16", shift)
    assert (f32 > thr).mean() > 0.2 and (f32 <= thr).mean() > 0.2
    np.testing.assert_allclose(bf16, f32, rtol=0, atol=0.01 * thr)
    clear = np.abs(f32 - thr) > 0.01 * thr
    assert clear.mean() > 0.5
    np.testing.assert_array_equal((bf16 > thr)[clear], (f32 > thr)[clear])
    fused = nearest("bfloat16", shift, "fused")
    np.testing.assert_allclose(fused, f32, rtol=0, atol=0.01 * thr)
    np.testing.assert_array_equal((fused > thr)[clear], (f32 > thr)[clear])


def test_subgoal_testing_precision_by_device_and_flag(monkeypatch):
    """Unset: float32 on a CPU, bfloat16 on a GPU; the flag wins on both; the chunk's
    program has bf16 matrix products only with bfloat16 (dhrl has no other bf16 pass). The
    kernel: fused on a GPU with bfloat16, xla otherwise or when asked for."""
    assert config.algo_config(TINY).subgoal_test_precision == "float32"
    bf16 = TINY.replace(subgoal_test_precision="bfloat16")
    assert config.algo_config(bf16).subgoal_test_precision == "bfloat16"

    def lowered(cfg: config.TrainConfig) -> str:
        init, chunk, _ = runner.build(cfg)
        carry = jax.eval_shape(init, jax.ShapeDtypeStruct((1, 2), jnp.uint32))
        return chunk.lower(carry, jnp.int32(0)).as_text()

    assert "bf16" not in lowered(TINY) and "bf16" in lowered(bf16)
    assert config.algo_config(TINY).subgoal_test_kernel == "xla"
    monkeypatch.setattr(dhrl.jax, "default_backend", lambda: "gpu")
    assert config.algo_config(TINY).subgoal_test_precision == "bfloat16"
    assert config.algo_config(TINY).subgoal_test_kernel == "fused"  # TINY's hidden: 2 ** n
    f32 = TINY.replace(subgoal_test_precision="float32")
    assert config.algo_config(f32).subgoal_test_precision == "float32"
    assert config.algo_config(f32).subgoal_test_kernel == "xla"
    xla = TINY.replace(value_kernel="xla")
    assert config.algo_config(xla).subgoal_test_kernel == "xla"


@pytest.mark.parametrize("low_value", ["infinite", "k_step"])
def test_flr_dhrl_trains_alike_with_the_fused_kernel(low_value):
    """flr_dhrl with --value-kernel fused (eq. 5's values and subgoal testing in the fused
    kernel; Pallas's interpreter here) against XLA's kernels, both with bf16 operands: three
    rounds (random, learning, the first graph), two runs vmapped: the same metrics and low-level
    critics to 1e-4 (measured: 2e-6; the summation orders differ). Also with the k-step value,
    whose networks take the steps left as one more input."""
    base = TINY.replace(algo="flr_dhrl", seeds=2, flr_precision="bfloat16",
                        subgoal_test_precision="bfloat16", low_value=low_value)
    out = {}
    for kernel in ("xla", "fused"):
        cfg = base.replace(value_kernel=kernel)
        assert config.algo_config(cfg).flr.value_kernel == kernel
        assert config.algo_config(cfg).subgoal_test_kernel == kernel
        # uncached (runner.build keeps every config's programs for the process's life)
        init, chunk, _ = runner._build.__wrapped__(cfg)
        carry = init(jax.random.split(jax.random.key(0), 2))
        for i in range(3):
            carry, m = chunk(carry, jnp.int32(i))
        out[kernel] = jax.tree.map(np.asarray, (m, carry.low.critic.params))
    (m_x, p_x), (m_f, p_f) = out["xla"], out["fused"]
    assert m_f["stats/graph_nodes"].min() >= 1 and np.isfinite(m_f["low/critic_loss"]).all()
    assert (m_f["stats/reach_reward_upright"] < 0).all()  # eq. 5's rewards were paid
    for name in ("low/critic_loss", "stats/reach_reward_upright", "low/q", "high/q",
                 "high/critic_loss"):
        np.testing.assert_allclose(m_f[name], m_x[name], rtol=1e-4, err_msg=name)
    for a, b in zip(jax.tree.leaves(p_f), jax.tree.leaves(p_x), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-4 * np.abs(b).max())


def test_each_reading_of_the_low_value_changes_the_low_level_alone():
    """--low-value reach_ends: the low level's main critics stop their targets at reaching
    transitions (tests/agents/gc_td3/test_losses.py); k_step: the subgoal period is its
    actor's and critics' horizon. The high level keeps neither."""
    for reading in ("infinite", "reach_ends", "k_step"):
        algo = config.algo_config(TINY.replace(algo="flr_dhrl", low_value=reading))
        assert algo.low.reach_ends == (reading == "reach_ends") and not algo.high.reach_ends
        assert algo.low.horizon == (algo.subgoal_freq if reading == "k_step" else None)
        assert algo.high.horizon is None


def test_flr_dhrl_trains_with_n_step_targets_and_categorical_critics(capsys):
    """--n-step 3 with --critic-atoms 11 trains (finite, non-zero critic losses after the
    graph's first rounds; the low level's main critics categorical, its distance critics and
    the high level's scalar); n-step refuses a low-level value that ends (reach_ends, k_step),
    the fused kernel categorical critics, and fewer than 2 atoms, each in one line."""
    cfg = TINY.replace(algo="flr_dhrl", n_step=3, critic_atoms=11)
    init, chunk, _ = runner.build(cfg)
    carry = init(jax.random.split(jax.random.key(0), 1))
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
    assert np.isfinite(np.asarray(m["low/critic_loss"])).all() and float(
        np.asarray(m["low/critic_loss"]).mean()) > 0
    assert bool(np.asarray(runner.params_finite(cfg.algo, carry)).all())
    heads = {name: net.params["params"]["MLP_0"]["TorchDense_3"]["bias"].shape[-1]
             for name, net in (("low", carry.low.critic), ("low_g", carry.low.critic_g),
                               ("high", carry.high.critic))}
    assert heads == {"low": 11, "low_g": 1, "high": 1}
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/never-made"]
    fused = ["--value-kernel", "fused", "--flr-precision", "bfloat16",
             "--subgoal-test-precision", "bfloat16"]
    for bad, says in ((["--n-step", "2", "--low-value", "reach_ends"], "needs --low-value"),
                      (["--n-step", "2", "--low-value", "k_step"], "needs --low-value"),
                      (["--critic-atoms", "11", *fused], "reads scalar critics"),
                      (["--critic-atoms", "1"], "0 or >= 2")):
        with pytest.raises(SystemExit):
            parse_args(base + bad)
        assert says in capsys.readouterr().err


def test_flr_dhrl_trains_with_normalised_low_level_inputs():
    """--obs-norm: the low level's state keeps statistics of the observations it learnt from
    (none during the random rounds, then every critic step's batch), the high level's inputs
    stay raw, and both train with finite losses and parameters (the fused kernel's inputs:
    tests/agents/gc_td3/test_fused_value.py); DHRL beside it in the program (alpha 0, whose
    candidate values FLR skips: flr.active_runs_value)."""
    cfg = TINY.replace(algo="flr_dhrl", obs_norm=True, flr_alpha=(0.0, 0.01))
    init, chunk, evaluate = runner.build(cfg)
    carry = init(jax.random.split(jax.random.key(0), 2))
    assert carry.high.obs_stats is None
    assert np.asarray(carry.low.obs_stats.std).min() == 1.0
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
    std = np.asarray(carry.low.obs_stats.std)
    assert std.shape[-1] == config.make_env(cfg).observation_size and (std != 1.0).all()
    assert np.isfinite(np.asarray(m["low/critic_loss"])).all()
    assert bool(np.asarray(runner.params_finite(cfg.algo, carry)).all())
    metrics = evaluate(carry, jax.random.split(jax.random.key(1), 2))
    assert np.isfinite(np.asarray(metrics["eval/success_rate"])).all()


def test_flr_dhrl_trains_and_evaluates_with_the_k_step_value():
    """--low-value k_step: the actor takes one more input (the steps left / k); two runs
    (alpha 0 and 0.01) train three rounds (random, learning, the first graph) with finite
    losses, acting with the period's steps left, and evaluate."""
    cfg = TINY.replace(algo="flr_dhrl", flr_alpha=(0.0, 0.01), low_value="k_step")
    init, chunk, evaluate = runner._build.__wrapped__(cfg)
    carry = init(jax.random.split(jax.random.key(0), 2))
    env = config.make_env(cfg)
    width = env.observation_size + 1 + env.maze.goal.shape[-1]
    assert any(x.shape[-2:] == (width, cfg.hidden)
               for x in jax.tree.leaves(carry.low.actor.params))
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
    assert np.isfinite(np.asarray(m["low/critic_loss"])).all() and m["stats/graph_nodes"].min() >= 1
    metrics = evaluate(carry, jax.random.split(jax.random.key(1), 2))
    assert np.isfinite(np.asarray(metrics["eval/success_rate"])).all()


def test_flr_dhrl_trains_with_layer_norm_critics():
    """--critic-layer-norm: every critic of both levels has its LayerNorms and the run trains
    (finite losses and parameters after the graph's first rounds); XLA's kernels on any
    backend (tests/agents/gc_td3/test_fused_value.py)."""
    cfg = dataclasses.replace(TINY, algo="flr_dhrl", critic_layer_norm=True)
    init, chunk, _ = runner.build(cfg)
    carry = init(jax.random.split(jax.random.key(0), 1))
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
    for agent in (carry.low, carry.high):
        for net in (agent.critic, agent.critic_g):
            assert "LayerNorm_0" in net.params["params"]["MLP_0"]
        assert "LayerNorm_0" not in agent.actor.params["params"]["MLP_0"]
    assert np.isfinite(np.asarray(m["low/critic_loss"])).all() and float(
        np.asarray(m["low/critic_loss"]).mean()) > 0
    assert bool(np.asarray(runner.params_finite(cfg.algo, carry)).all())
