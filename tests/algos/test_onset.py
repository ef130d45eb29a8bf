"""The onset metrics of the shared hierarchy: the rank correlation, the graph's and the
subgoals' quality against the maze's true path lengths, on hand-made cases."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
from scipy.stats import spearmanr

from flrjax import planner, replay
from flrjax.algos import hierarchy, onset
from flrjax.envs import geodesic
from flrjax.envs.maze import U_MAZE, Maze

MAZE = Maze(U_MAZE)
K = 8  # landmark slots of every hand-made graph: one compilation
_from_distances = jax.jit(planner.graph_from_distances, static_argnames="cutoff")
_graph_stats = jax.jit(onset.graph_stats, static_argnums=2)


def _graph(goals: np.ndarray, pdist: np.ndarray) -> tuple[planner.Graph, jax.Array]:
    """A graph (cutoff 5) on the landmarks ``goals`` (the first ``len(goals)`` of :data:`K`
    slots) and its distance matrix."""
    n, k = len(goals), K
    full = np.zeros((k, 2), np.float32)
    full[:n] = goals
    d = np.full((k, k), 1e3, np.float32)
    d[:n, :n] = pdist
    lm = planner.Landmarks(index=jnp.arange(k), state=jnp.asarray(full), goal=jnp.asarray(full),
                           mask=jnp.arange(k) < n)
    return _from_distances(lm, jnp.asarray(d), cutoff=5.0), jnp.asarray(d)


def test_rank_corr_is_spearman_over_the_mask_with_ties():
    rng = np.random.default_rng(0)
    x = rng.integers(0, 6, (9, 9)).astype(np.float32)  # many ties
    y = x + rng.normal(0, 2, x.shape).astype(np.float32)
    mask = rng.random(x.shape) < 0.7
    y_noise = np.where(mask, y, np.nan)  # what lies outside the mask is never read
    got = onset.rank_corr(jnp.asarray(x), jnp.asarray(y_noise), jnp.asarray(mask))
    np.testing.assert_allclose(got, spearmanr(x[mask], y[mask]).statistic, rtol=1e-5)
    assert np.isnan(onset.rank_corr(jnp.ones(4), jnp.arange(4.0), jnp.ones(4, bool)))


def test_a_perfect_critic_ranks_like_the_maze_and_a_reversed_one_against_it():
    """Landmarks on both arms of the U: a critic whose distances grow with the true path
    (any monotone map) has rank correlation 1; one that shrinks with it, -1."""
    goals = np.array([[0, 0], [8, 0], [16, 0], [16, 8], [16, 16], [8, 16], [0, 16]], np.float32)
    geo = geodesic.table(MAZE)
    true = np.asarray(geodesic.distance(geo, goals[:, None], goals[None]))
    for pdist, want in ((3 * np.sqrt(true), 1.0), (100 - true, -1.0)):
        graph, d = _graph(goals, pdist)
        stats = _graph_stats(graph, d, MAZE)
        np.testing.assert_allclose(stats["dist_rank_corr"], want, rtol=1e-5)


def test_wall_edges_coverage_and_the_path_to_the_goal():
    """Four landmarks: two by the start, one by the goal (across the inner wall from them) and
    one far up the right arm. A critic that thinks the start and the goal are near joins them
    by edges that cross the wall; the goal's nearest landmark is 1 away along the maze."""
    goals = np.array([[0, 0], [2, 0], [0, 15], [16, 12]], np.float32)
    near = np.array([[0, 1, 2, 9], [1, 0, 2, 9], [2, 2, 0, 9], [9, 9, 9, 0]], np.float32)
    graph, d = _graph(goals, near)
    stats = jax.tree.map(float, _graph_stats(graph, d, MAZE))
    # edges: 0<->1, 0<->2, 1<->2 (under the cutoff) and 3 -> each (its nearest, all at 9)
    edges = np.isfinite(np.asarray(graph.weight)) & ~np.eye(K, dtype=bool)
    assert edges.sum() == 9
    np.testing.assert_allclose(stats["wall_edge_frac"], 4 / 9)  # 0<->2, 1<->2 cross the wall
    assert stats["path_to_goal"] == 1.0
    assert abs(stats["goal_landmark_gap"] - 1.0) <= 2 * geodesic.table(MAZE).size
    # no edge from the start's landmarks to the goal's: no path
    far = near.copy()
    far[:2, 2] = far[2, :2] = 9
    graph, d = _graph(goals, far)
    assert float(_graph_stats(graph, d, MAZE)["path_to_goal"]) == 0.0


def test_empty_graph_has_nan_stats_and_no_rebuild_gives_nan():
    graph = planner.empty_graph(K, 2, 2)
    stats = _graph_stats(graph, jnp.zeros((K, K)), MAZE)
    assert all(np.isnan(float(v)) for v in stats.values())
    cfg = SimpleNamespace(graph_start_round=1, graph_every=2)
    built, _ = _graph(np.array([[0, 0], [8, 0]], np.float32), np.eye(2, dtype=np.float32))

    def build():
        return built, {k: jnp.float32(1.0) for k in onset.BUILD_STATS}

    refresh = jax.jit(lambda episode: hierarchy.refresh_graph(episode, cfg, build, graph))
    for episode, rebuilt in ((0, False), (1, True), (2, False), (3, True)):
        g, stats = refresh(jnp.int32(episode))
        assert bool(g.landmarks.mask.any()) == rebuilt
        for v in stats.values():
            assert float(v) == 1.0 if rebuilt else np.isnan(float(v))


def test_reach_stats_read_the_sample_and_the_complete_episodes():
    """A replay of three slots on the U: an episode standing at the start and one at the top
    right corner, complete, and one by the goal still being written. The replay's gap is the
    corner's (the episode in flight is not sampleable), the sample's that of the states it
    is given; an empty replay gives NaN."""
    spec = {"achieved_goal": jax.ShapeDtypeStruct((2,), jnp.float32)}
    empty = replay.init(3, 2, 1, spec, {})

    def standing(xy):  # one episode of 3 states at xy
        return {"achieved_goal": jnp.broadcast_to(jnp.float32(xy), (1, 3, 2))}

    buffer = replay.insert_episodes(empty, standing((0, 0)))
    buffer = replay.insert_episodes(buffer, standing((16, 16)))
    buffer = replay.insert_step(buffer, 0, {"achieved_goal": jnp.float32([[0, 15]])})
    geo = geodesic.table(MAZE)
    sampled = jnp.float32([[16, 12], [0, 0]])
    stats = jax.jit(onset.reach_stats, static_argnums=0)(MAZE, sampled, buffer)
    np.testing.assert_allclose(stats["replay_goal_gap"],
                               geodesic.distance(geo, jnp.float32([16, 16]), MAZE.goal))
    np.testing.assert_allclose(stats["sample_goal_gap"],
                               geodesic.distance(geo, jnp.float32([16, 12]), MAZE.goal))
    assert 0 < stats["replay_goal_gap"] < stats["sample_goal_gap"]
    none = onset.reach_stats(MAZE, sampled, empty)
    assert all(np.isnan(float(v)) for v in none.values())


def test_subgoal_stats_measure_progress_along_the_maze():
    """Two envs at the start of the U with the goal at its other end: a subgoal at the goal
    is all the way (progress = the whole path), one straight across the wall beside the start
    is nearly none, though it is nearer the goal in a straight line; the period's progress is
    where the agent ended."""
    geo = geodesic.table(MAZE)
    goal = jnp.asarray(MAZE.goal)
    start_xy = jnp.array([[0.5, 0.5], [0.5, 0.5]])
    end_xy = jnp.array([[16.5, 0.5], [0.5, 0.5]])
    state = lambda xy: SimpleNamespace(info={"achieved_goal": xy,  # noqa: E731
                                             "goal": jnp.stack([goal, goal])})
    subgoal = jnp.stack([goal, jnp.array([0.5, 3.5])])
    stats = jax.tree.map(float, onset.subgoal_stats(MAZE, state(start_xy), state(end_xy),
                                                        subgoal))
    whole = float(geodesic.distance(geo, start_xy[0], goal))
    to_side = float(geodesic.distance(geo, subgoal[1], goal))
    np.testing.assert_allclose(stats["subgoal_progress"], (whole + whole - to_side) / 2)
    assert abs(whole - to_side) < 4  # beside the start, across the wall from the goal
    after = float(geodesic.distance(geo, end_xy[0], goal))
    np.testing.assert_allclose(stats["period_progress"], (whole - after) / 2)
    np.testing.assert_allclose(stats["subgoal_distance"], (whole + 3.0) / 2)
