"""Tests for flrjax.planner against NumPy/SciPy translations of the DHRL reference rules."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.sparse.csgraph import csgraph_from_dense, dijkstra, shortest_path

from flrjax import planner as P

INF = np.inf


# --------------------------------------------------------------------------------------------
# NumPy translations of the reference (DHRL/rl/algo/graph.py) used as oracles
# --------------------------------------------------------------------------------------------


def ref_fps(matrix: np.ndarray, start: int, n_select: int, eps: float) -> list[int]:
    """graph.py fps_selection, with the first pick given (the reference's is index 0)."""
    dists = np.full(matrix.shape[0], 1e6)
    chosen: list[int] = []
    while len(chosen) < n_select:
        if dists.max() < eps and len(chosen) > n_select / 10:
            break
        idx = start if not chosen else int(np.argmax(dists))
        chosen.append(idx)
        new = matrix[idx].copy()
        new[idx] = 0
        dists = np.minimum(dists, new)
    return chosen


def ref_edges(pdist: np.ndarray, cutoff: float) -> np.ndarray:
    """graph.py graph_construct double loop; inf where no edge."""
    n = pdist.shape[0]
    w = np.full((n, n), INF)
    for i in range(n):
        min_from_i = min(np.delete(pdist[i], i))
        for j in range(n):
            if pdist[i, j] < cutoff or pdist[i, j] < min_from_i * 1.2:
                w[i, j] = pdist[i, j]
    return w


def ref_find_path(pdist, start_d, goal_d, start_goal, cutoff):
    """graph.py find_path with SciPy Dijkstra instead of networkx: (path, edge lengths, cost)."""
    k = len(start_d)
    s_node, g_node = k, k + 1
    g = np.full((k + 2, k + 2), INF)
    g[:k, :k] = ref_edges(pdist, cutoff)
    np.fill_diagonal(g, INF)  # self-loops never lie on a shortest path
    g[s_node, :k] = np.where(start_d < cutoff, start_d, INF)
    g[:k, g_node] = np.where(goal_d < cutoff, goal_d, INF)
    if start_goal < cutoff:
        g[s_node, g_node] = start_goal
    if not np.isfinite(g[s_node]).any():  # 'start' not in the graph
        g[s_node, :k] = np.where(start_d < start_d.min() * 1.5, start_d, INF)
    dist, pred = dijkstra(
        csgraph_from_dense(g, null_value=INF),
        directed=True,
        indices=s_node,
        return_predecessors=True,
    )

    def back(node):
        path = []
        while node != s_node:
            path.append(int(node))
            node = pred[node]
        return path[::-1]

    if np.isfinite(dist[g_node]):
        path = back(g_node)[:-1]
        nodes = [s_node, *path, g_node]
        edges = [g[a, b] for a, b in zip(nodes[:-1], nodes[1:], strict=True)]
        return path, edges, dist[g_node], True
    goal_edge = goal_d.copy()
    while np.isfinite(goal_edge).any():
        nearest = int(np.argmin(goal_edge))
        if np.isfinite(dist[nearest]):
            path = back(nearest)
            nodes = [s_node, *path]
            edges = [g[a, b] for a, b in zip(nodes[:-1], nodes[1:], strict=True)]
            return path, [*edges, goal_d[nearest]], dist[nearest] + goal_d[nearest], False
        goal_edge[nearest] = INF
    return [], [], INF, False


def ref_get_waypoint(state: dict, waypoints, edge_lengths, ob, subgoal):
    """graph.py get_waypoint on a dict state."""
    state["chase"] += 1
    if state["idx"] >= len(waypoints):
        return subgoal
    too_long = state["chase"] > edge_lengths[state["idx"]]
    if too_long or np.linalg.norm(ob - waypoints[state["idx"]]) < 0.5:
        state["idx"] += 1
        state["chase"] = 0
    return subgoal if state["idx"] >= len(waypoints) else waypoints[state["idx"]]


# --------------------------------------------------------------------------------------------
# Helpers. Every hand-made graph is padded to K landmarks (the padding masked out) and every
# plan has room for L waypoints, so each jitted function compiles once for the whole file.
# --------------------------------------------------------------------------------------------

K, L, OBS_DIM = 24, 12, 5

_build = jax.jit(P.graph_from_distances)
_plan = jax.jit(P.shortest_path, static_argnames="max_path_len")
f32 = np.float32


def build(landmarks: P.Landmarks, pdist, *, cutoff: float) -> P.Graph:
    """Jitted graph_from_distances; float32 inputs so that every call hits the same compilation."""
    return _build(landmarks, f32(pdist), cutoff=f32(cutoff))


def plan(graph, start_d, goal_d, start_goal, *, cutoff, max_path_len=L, start_factor=1.5):
    """Jitted plan with float32 inputs (Python floats are weakly typed: a new compilation)."""
    return _plan(
        graph,
        f32(start_d),
        f32(goal_d),
        f32(start_goal),
        cutoff=f32(cutoff),
        start_factor=f32(start_factor),
        max_path_len=max_path_len,
    )


edge_weights = jax.jit(P.edge_weights)
advance = jax.jit(P.advance)


def euclid(obs, goal):
    """Oracle steps-to-reach in the open (NumPy or JAX arrays)."""
    return ((obs[:, :2] - goal) ** 2).sum(-1) ** 0.5


def obs_at(xy) -> np.ndarray:
    """An observation whose first two entries are the achieved goal (x, y)."""
    xy = np.asarray(xy, np.float32)
    return np.concatenate([xy, np.ones((*xy.shape[:-1], OBS_DIM - 2), np.float32)], axis=-1)


def landmarks_at(points, mask=None) -> P.Landmarks:
    """Landmarks at ``points`` padded to K with invalid ones (placed where they would win)."""
    points = np.asarray(points, np.float32)
    n = len(points)
    goal = np.concatenate([points, np.zeros((K - n, 2), np.float32)])
    valid = np.arange(K) < n if mask is None else np.asarray(mask, bool)
    return P.Landmarks(index=np.arange(K), state=obs_at(goal), goal=goal, mask=valid)


def pad(x, fill=0.0) -> np.ndarray:
    """Pad per-landmark inputs to K; the padding (0 = 'right here') must be ignored."""
    x = np.asarray(x, np.float32)
    return np.concatenate([x, np.full(K - len(x), fill, np.float32)])


def np_pairwise(dist_fn, obs, goal) -> np.ndarray:
    """``D[i, j] = dist_fn(obs[i], goal[j])`` in NumPy (the planner's own is tested below)."""
    n, m = len(obs), len(goal)
    return dist_fn(np.repeat(obs, m, 0), np.tile(goal, (n, 1))).reshape(n, m)


def graph_of(points, dist_fn=euclid, cutoff=2.5) -> P.Graph:
    lm = landmarks_at(points)
    return build(lm, np_pairwise(dist_fn, lm.state, lm.goal), cutoff=cutoff)


def path_list(path: P.Path) -> list[int]:
    return [int(x) for x in np.asarray(path.landmark)[: int(path.length)]]


def random_digraph(rng: np.random.Generator, n: int, p: float = 0.12) -> np.ndarray:
    w = rng.uniform(0.5, 5.0, (n, n))
    adj = rng.random((n, n)) < p
    np.fill_diagonal(adj, False)
    adj[:, -2:] = False  # two sources nobody can reach
    return np.where(adj, w, INF).astype(np.float32)


# --------------------------------------------------------------------------------------------
# All-pairs shortest paths
# --------------------------------------------------------------------------------------------


def test_apsp_matches_scipy_and_next_hop_paths():
    rng = np.random.default_rng(0)
    n_seeds, n = 5, 30
    weights = np.stack([random_digraph(rng, n) for _ in range(n_seeds)])
    dist_b, hop_b = jax.jit(jax.vmap(P.all_pairs_shortest_paths))(jnp.asarray(weights))
    dist_b, hop_b = np.asarray(dist_b), np.asarray(hop_b)  # leading seed axis

    for s in range(n_seeds):
        w = weights[s].astype(np.float64)
        expected = shortest_path(csgraph_from_dense(w, null_value=INF), method="D", directed=True)
        assert np.isinf(expected).any() and np.isfinite(expected).sum() > 2 * n
        np.testing.assert_allclose(dist_b[s], expected, rtol=1e-5)
        np.testing.assert_array_equal(hop_b[s] < 0, np.isinf(expected))
        for i, j in zip(*np.nonzero(np.isfinite(expected)), strict=True):
            node, total, steps = i, 0.0, 0
            while node != j:  # follow next hops; their weights must add up to the distance
                nxt = hop_b[s, node, j]
                total += w[node, nxt]
                node, steps = nxt, steps + 1
                assert steps <= n
            assert total == pytest.approx(expected[i, j], rel=1e-5)


# --------------------------------------------------------------------------------------------
# Farthest-point sampling
# --------------------------------------------------------------------------------------------

fps_matrix = jax.jit(P.farthest_point_sampling, static_argnames="max_nodes")


def test_fps_matches_bruteforce_numpy():
    rng = np.random.default_rng(1)
    pts = rng.random((200, 2)).astype(np.float32)
    # Asymmetric "distance": checks FPS uses rows d(landmark -> x), as the reference does.
    skew = 1.0 + 0.5 * rng.random((200, 200)).astype(np.float32)
    matrix = np.linalg.norm(pts[:, None] - pts[None], axis=-1) * skew
    expected = ref_fps(matrix, start=0, n_select=40, eps=0.0)
    assert len(expected) == 40

    lm = fps_matrix(0, jnp.asarray(matrix), jnp.asarray(pts), max_nodes=40, stop_eps=0.0)
    np.testing.assert_array_equal(lm.index, expected)
    assert bool(lm.mask.all())
    np.testing.assert_array_equal(lm.goal, pts[expected])
    np.testing.assert_array_equal(lm.state, pts[expected])

    # Same through a batched distance function (one call of N pairs per landmark).
    lm_fn = jax.jit(lambda s: P.farthest_point_sampling(3, euclid, s, max_nodes=40, stop_eps=0.0))(
        jnp.asarray(pts)
    )
    sym = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.testing.assert_array_equal(lm_fn.index, ref_fps(sym, 3, 40, 0.0))


def test_fps_early_stop_and_mask():
    rng = np.random.default_rng(2)
    pts = rng.random((200, 2)).astype(np.float32)
    matrix = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    eps, max_nodes = 0.25, 40
    expected = ref_fps(matrix, start=0, n_select=max_nodes, eps=eps)
    assert max_nodes // 10 < len(expected) < max_nodes  # the early stop did trigger

    lm = fps_matrix(0, jnp.asarray(matrix), jnp.asarray(pts), max_nodes=max_nodes, stop_eps=eps)
    mask, n_valid = np.asarray(lm.mask), len(expected)
    assert mask[:n_valid].all() and not mask[n_valid:].any()
    np.testing.assert_array_equal(np.asarray(lm.index)[:n_valid], expected)
    cover = matrix[np.asarray(lm.index)[mask]].min(axis=0)
    assert cover.max() < eps  # every state is within eps of a landmark

    # Huge eps: the reference still picks more than n_graph_node / 10 landmarks.
    lm = fps_matrix(0, jnp.asarray(matrix), jnp.asarray(pts), max_nodes=max_nodes, stop_eps=1e9)
    assert int(lm.mask.sum()) == len(ref_fps(matrix, 0, max_nodes, 1e9)) == max_nodes // 10 + 1


def test_start_index_accepts_keys_and_indices():
    valid = np.arange(64) < 40
    for key in (jax.random.key(0), jax.random.PRNGKey(0)):  # typed and legacy uint32[2]
        out = jax.eval_shape(P._start_index, key, valid)  # trace only: no compile
        assert out.shape == () and out.dtype == jnp.int32
    assert int(P._start_index(7, valid)) == 7
    with pytest.raises(TypeError):
        P._start_index(np.zeros(3, np.float32), valid)


# --------------------------------------------------------------------------------------------
# Edge rules
# --------------------------------------------------------------------------------------------


def test_edge_rules_cutoff_and_nearest_neighbour():
    n = 25  # the hand-made 4 nodes padded with invalid ones, so one compile serves all cases
    pdist = np.full((n, n), 1.0, np.float32)  # padding would be everybody's nearest neighbour
    pdist[:4, :4] = [
        [0.0, 5.0, 40.0, 50.0],
        [5.0, 0.0, 35.0, 38.0],
        [45.0, 35.0, 0.0, 41.0],  # nothing below cutoff: keep edges < 1.2 * 35 = 42
        [50.0, 38.0, 20.0, 0.0],
    ]
    mask = np.arange(n) < 4
    w = np.asarray(edge_weights(pdist, mask, cutoff=10.0))
    edges = np.isfinite(w)
    assert edges[0, :4].tolist() == [True, True, False, False]
    assert edges[2, :4].tolist() == [False, True, True, True]  # 45 >= 42 dropped, 41 kept
    assert not edges[4:].any() and not edges[:, 4:].any()  # invalid nodes: no edge at all
    np.testing.assert_array_equal(w[:4, :4], ref_edges(pdist[:4, :4], 10.0))

    # Node 3 invalid as well: it is not node 2's nearest neighbour any more.
    pdist[2, 3] = 20.0  # if it counted: 1.2 * 20 = 24 < 35 would drop 2 -> 1
    w = np.asarray(edge_weights(pdist, np.arange(n) < 3, cutoff=10.0))
    assert not np.isfinite(w[3]).any() and not np.isfinite(w[:, 3]).any()
    assert np.isfinite(w[2, 1])

    rng = np.random.default_rng(4)
    for _ in range(3):
        pdist = rng.uniform(0.0, 60.0, (n, n)).astype(np.float32)
        w = edge_weights(pdist, np.ones(n, bool), cutoff=30.0)
        np.testing.assert_array_equal(np.asarray(w), ref_edges(pdist, 30.0))


# --------------------------------------------------------------------------------------------
# Planning
# --------------------------------------------------------------------------------------------


def _random_instance(rng: np.random.Generator):
    pts = rng.uniform(0.0, 10.0, (K, 2)).astype(np.float32)
    pdist = np.linalg.norm(pts[:, None] - pts[None], axis=-1) * rng.uniform(1.0, 1.3, (K, K))
    start, subgoal = rng.uniform(-5.0, 15.0, (2, 2))
    start_d = np.linalg.norm(pts - start, axis=-1) * rng.uniform(1.0, 1.3, K)
    goal_d = np.linalg.norm(pts - subgoal, axis=-1) * rng.uniform(1.0, 1.3, K)
    start_goal = np.linalg.norm(start - subgoal) * 1.1
    mask = rng.random(K) < 0.85
    return pts, pdist.astype(f32), start_d.astype(f32), goal_d.astype(f32), f32(start_goal), mask


def test_plan_matches_reference_find_path():
    """Random instances that hit every branch of find_path, against the NumPy/SciPy oracle."""
    rng = np.random.default_rng(5)
    cutoff = 2.5
    branches = {"direct": 0, "via": 0, "nearest": 0, "start_fallback": 0, "truncated": 0}
    for _ in range(96):
        pts, pdist, start_d, goal_d, start_goal, mask = _random_instance(rng)
        lm = P.Landmarks(index=np.arange(K), state=obs_at(pts), goal=pts, mask=mask)
        graph = build(lm, pdist, cutoff=cutoff)
        path = jax.tree.map(
            np.asarray, plan(graph, start_d, goal_d, start_goal, cutoff=cutoff, max_path_len=L)
        )
        ids = np.nonzero(mask)[0]
        ref_path, ref_edge, ref_cost, ref_found = ref_find_path(
            pdist[np.ix_(ids, ids)].astype(np.float64),
            start_d[ids].astype(np.float64),
            goal_d[ids].astype(np.float64),
            float(start_goal),
            cutoff,
        )
        on_path = [int(ids[i]) for i in ref_path][:L]
        n = int(path.length)
        assert path.landmark[:n].tolist() == on_path
        assert (path.landmark[n:] == -1).all()
        assert bool(path.truncated) == (len(ref_path) > L)
        assert bool(path.reaches_subgoal) == ref_found
        assert float(path.cost) == pytest.approx(ref_cost, rel=1e-5)
        np.testing.assert_allclose(path.edge_len[:n], ref_edge[:-1][:L], rtol=1e-5)
        np.testing.assert_allclose(path.waypoint[:n], pts[on_path])
        branches["direct"] += ref_found and not ref_path
        branches["via"] += ref_found and bool(ref_path)
        branches["nearest"] += not ref_found
        branches["start_fallback"] += not (start_d[ids] < cutoff).any()
        branches["truncated"] += len(ref_path) > L
    assert min(v for k, v in branches.items() if k != "truncated") >= 3, branches


LINE = [(0.0, 0.0), (2.0, 0.0), (4.0, 0.0)]


def test_plan_start_fallback_when_start_has_no_edge():
    graph = graph_of(LINE)
    start_d = pad([10.0, 11.0, 16.0])  # none < cutoff: edges < 1.5 * 10 = 15 -> {0, 1}
    goal_d = pad([5.0, 3.0, 0.5])
    path = plan(graph, start_d, goal_d, 20.0, cutoff=2.5, max_path_len=L)
    assert path_list(path) == [1, 2]
    np.testing.assert_allclose(path.edge_len[:2], [11.0, 2.0])
    assert bool(path.reaches_subgoal) and float(path.cost) == pytest.approx(13.5)
    np.testing.assert_allclose(path.waypoint[:2], [LINE[1], LINE[2]])
    # With no fallback edge (factor 1) the start is isolated: no waypoint, chase the subgoal.
    path = plan(graph, start_d, goal_d, 20.0, cutoff=2.5, max_path_len=L, start_factor=1.0)
    assert int(path.length) == 0 and not bool(path.reaches_subgoal)
    assert np.isinf(float(path.cost))


def test_plan_unreachable_subgoal_goes_to_nearest_reachable_landmark():
    graph = graph_of([(0.0, 0.0), (2.0, 0.0), (20.0, 0.0), (22.0, 0.0)])  # {0, 1} and {2, 3}
    assert np.isinf(float(graph.dist[0, 3])) and np.isinf(float(graph.dist[3, 0]))
    start_d = pad([1.0, 3.0, 10.0, 12.0])  # the start has an edge: no start fallback
    goal_d = pad([9.0, 8.0, 4.0, 1.0])  # 3 is the nearest but unreachable
    path = plan(graph, start_d, goal_d, 30.0, cutoff=2.5, max_path_len=L)
    assert path_list(path) == [0, 1]
    np.testing.assert_allclose(path.edge_len[:2], [1.0, 2.0])
    assert not bool(path.reaches_subgoal)
    assert float(path.cost) == pytest.approx(1.0 + 2.0 + 8.0)


def test_plan_direct_edge_truncation_and_empty_graph():
    graph = graph_of(LINE)
    start_d, goal_d = pad([0.3, 2.6, 4.1]), pad([4.0, 2.6, 0.2])
    direct = plan(graph, start_d, goal_d, 1.0, cutoff=2.5, max_path_len=L)
    assert int(direct.length) == 0 and bool(direct.reaches_subgoal)
    assert float(direct.cost) == pytest.approx(1.0)
    via = plan(graph, start_d, goal_d, 10.0, cutoff=2.5, max_path_len=L)
    assert path_list(via) == [0, 1, 2] and not bool(via.truncated)
    assert float(via.cost) == pytest.approx(4.5)
    # A 14-landmark corridor needs more than L = 12 waypoints: keep the first L.
    long_line = [(2.0 * i, 0.0) for i in range(14)]
    xs = np.arange(14, dtype=np.float32) * 2.0
    cut = plan(
        graph_of(long_line),
        pad(np.abs(xs + 0.5)),
        pad(np.abs(xs - 26.5)),
        100.0,
        cutoff=2.5,
        max_path_len=L,
    )
    assert path_list(cut) == list(range(L)) and bool(cut.truncated)

    empty = jax.jit(P.empty_graph, static_argnums=(0, 1, 2))(K, OBS_DIM, 2)  # before 1st build
    far = np.array([40.0, 40.0], np.float32)
    path = plan(empty, pad([]), pad([]), 56.6, cutoff=30.0, max_path_len=L)
    assert int(path.length) == 0 and not bool(path.reaches_subgoal)
    _, waypoint = advance(P.follower_init(), path, np.zeros(2, np.float32), far)
    np.testing.assert_allclose(waypoint, far)
    to_graph = jax.jit(P.graph_to_goal_distance)
    assert np.isinf(float(to_graph(empty, pad([]))))
    assert float(to_graph(graph, goal_d)) == pytest.approx(0.2)


# U-shaped maze: a thin wall on y = 1 for x <= 6.5; the passage is at x in (6.5, 8.5].
WALL_Y, WALL_END = 1.0, 6.5


def crosses_wall(p, q):
    dy = q[..., 1] - p[..., 1]
    opposite = (p[..., 1] - WALL_Y) * (q[..., 1] - WALL_Y) < 0
    t = (WALL_Y - p[..., 1]) / (dy + (dy == 0))  # NumPy or JAX arrays
    x = p[..., 0] + t * (q[..., 0] - p[..., 0])
    return opposite & (x <= WALL_END)


def maze_dist(obs, goal):
    """Oracle steps-to-reach: Euclidean, or 100 through the wall."""
    blocked = crosses_wall(obs[:, :2], goal)
    return blocked * 100.0 + (1 - blocked) * euclid(obs, goal)  # NumPy or JAX arrays


U_LANDMARKS = [(0, 0), (2, 0), (4, 0), (6, 0), (8, 0), (8, 2), (6, 2), (4, 2), (2, 2), (0, 2)]


def _plan_in_maze(dist_fn, start_xy, subgoal):
    """Hand-made U landmarks; distances from ``dist_fn`` evaluated in NumPy."""
    lm = landmarks_at(U_LANDMARKS)
    graph = graph_of(U_LANDMARKS, dist_fn)
    start = obs_at(np.broadcast_to(start_xy, (K, 2)))
    start_d = dist_fn(start, lm.goal)
    goal_d = dist_fn(lm.state, np.broadcast_to(subgoal, (K, 2)))
    start_goal = dist_fn(start[:1], subgoal[None])[0]
    return plan(graph, start_d, goal_d, start_goal, cutoff=2.5, max_path_len=L)


def test_u_maze_plan_goes_around_the_wall():
    start, subgoal = np.array([0.0, -0.6], np.float32), np.array([0.0, 2.6], np.float32)
    path = _plan_in_maze(maze_dist, start, subgoal)
    assert path_list(path) == [1, 2, 3, 4, 5, 6, 7, 8]
    assert bool(path.reaches_subgoal)
    np.testing.assert_allclose(path.waypoint[:8], U_LANDMARKS[1:9])
    np.testing.assert_allclose(path.edge_len[:8], [np.hypot(2, 0.6)] + [2.0] * 7, rtol=1e-6)
    assert float(path.cost) == pytest.approx(2 * np.hypot(2, 0.6) + 14.0, rel=1e-6)
    # Without the wall the same landmarks give the short cut (0,0) -> (0,2).
    assert path_list(_plan_in_maze(euclid, start, subgoal)) == [0, 9]


def test_graph_construct_and_find_path_vmapped_over_seeds():
    """Per seed: FPS landmarks from random free-space samples of the U maze, then plan.

    This is the planner's use in training: graph rebuild and planning ``vmap``-ped over seeds.

    Seed 1 sees only half of the replay (the rest invalid); seed 2 has an empty replay, which
    must give an empty graph and the subgoal itself as the waypoint.
    """
    rng = np.random.default_rng(6)
    xy = rng.uniform([-0.5, -0.5], [8.5, 2.5], (600, 2))
    xy = xy[~((np.abs(xy[:, 1] - WALL_Y) < 0.15) & (xy[:, 0] <= WALL_END))][:400]
    states = obs_at(xy)
    valid = np.ones((3, 400), bool)
    valid[1, 200:] = False
    valid[2] = False
    keys = jax.random.split(jax.random.key(0), 3)
    obs, subgoal = obs_at([0.0, -0.3]), np.array([0.0, 2.3], np.float32)

    @jax.jit
    @jax.vmap
    def run(key, valid):
        graph = P.graph_construct(
            key, maze_dist, states, states[:, :2], valid, max_nodes=K, stop_eps=1.2, cutoff=3.0
        )
        return graph, P.find_path(graph, maze_dist, obs, subgoal, cutoff=3.0, max_path_len=L)

    graphs, paths = jax.tree.map(np.asarray, run(keys, valid))
    assert graphs.landmarks.index[0, 0] != graphs.landmarks.index[1, 0]  # key -> random start
    assert (graphs.landmarks.index[1] < 200).all()
    for seed in (0, 1):
        assert K // 10 < graphs.landmarks.mask[seed].sum() < K  # FPS stopped early
        graph, path = jax.tree.map(lambda x, seed=seed: x[seed], (graphs, paths))
        # The vmapped plan equals the single-seed one on the same distances.
        lm = graph.landmarks
        start_d = maze_dist(np.broadcast_to(obs, (K, OBS_DIM)), lm.goal)
        goal_d = maze_dist(lm.state, np.broadcast_to(subgoal, (K, 2)))
        single = plan(graph, start_d, goal_d, 100.0, cutoff=3.0, max_path_len=L)
        jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5), single, path)
        assert path.reaches_subgoal and path.length >= 3
        pts = np.concatenate([obs[None, :2], path.waypoint[: path.length], subgoal[None]])
        assert not crosses_wall(pts[:-1], pts[1:]).any()
        assert pts[:, 0].max() > WALL_END  # it went round the end of the wall

    assert not graphs.landmarks.mask[2].any()
    # graph_with_distances: the same graph, with every landmark pair's distance before the cutoff
    graph, pdist = jax.tree.map(np.asarray, P.graph_with_distances(
        0, maze_dist, states, states[:, :2], max_nodes=K, stop_eps=1.2, cutoff=3.0))
    lm = graph.landmarks
    want = maze_dist(np.repeat(lm.state, K, 0), np.tile(lm.goal, (K, 1))).reshape(K, K)
    np.testing.assert_allclose(pdist, want, rtol=1e-6)
    jax.tree.map(np.testing.assert_array_equal, graph, P.graph_construct(
        0, maze_dist, states, states[:, :2], max_nodes=K, stop_eps=1.2, cutoff=3.0))
    empty_path = jax.tree.map(lambda x: x[2], paths)
    assert empty_path.length == 0 and not empty_path.reaches_subgoal
    _, waypoint = advance(P.follower_init(), empty_path, obs[:2], subgoal)
    np.testing.assert_allclose(waypoint, subgoal)


# --------------------------------------------------------------------------------------------
# Waypoint follower
# --------------------------------------------------------------------------------------------


def _scripted_path():
    waypoints = np.array([(2.0, 0.0), (4.0, 0.0), (6.0, 0.0)], np.float32)
    edge_len = np.array([3.0, 2.5, 10.0], np.float32)
    n_pad = L - 3
    return (
        waypoints,
        edge_len,
        P.Path(
            landmark=jnp.asarray([7, 8, 9] + [-1] * n_pad),
            waypoint=jnp.asarray(np.concatenate([waypoints, np.zeros((n_pad, 2), np.float32)])),
            edge_len=jnp.asarray(np.concatenate([edge_len, np.zeros(n_pad, np.float32)])),
            length=jnp.asarray(3),
            reaches_subgoal=jnp.asarray(True),
            cost=jnp.asarray(20.0),
            truncated=jnp.asarray(False),
        ),
    )


def test_advance_scripted_sequence():
    waypoints, edge_len, path = _scripted_path()
    subgoal = np.array([8.0, 0.0], np.float32)
    # (achieved goal, index of the waypoint the reference's get_waypoint returns that step)
    script = [
        ((0.0, 0.0), 0),  # chase 1 <= 3
        ((0.0, 0.0), 0),  # chase 2
        ((0.0, 0.0), 0),  # chase 3, not > 3 yet
        ((0.0, 0.0), 1),  # chase 4 > 3: give up on waypoint 0
        ((0.0, 0.0), 1),  # chase 1
        ((0.0, 0.0), 1),  # chase 2 <= 2.5
        ((0.0, 0.0), 2),  # chase 3 > 2.5
        ((5.8, 0.1), 3),  # within 0.5 of waypoint 2: on to the subgoal
        ((5.8, 0.1), 3),
    ]
    ag_seq = jnp.asarray([a for a, _ in script], jnp.float32)
    expected = np.array([subgoal if i >= 3 else waypoints[i] for _, i in script])

    def step(state, ag):
        state, wp = P.advance(state, path, ag, jnp.asarray(subgoal))
        return state, (wp, state.index)

    final, (wps, idx) = jax.jit(lambda s, a: jax.lax.scan(step, s, a))(P.follower_init(), ag_seq)
    np.testing.assert_allclose(wps, expected)
    assert np.asarray(idx).tolist() == [i for _, i in script]
    assert int(final.index) == 3

    ref_state = {"idx": 0, "chase": 0}
    ref = [
        ref_get_waypoint(ref_state, waypoints, edge_len, np.asarray(a), subgoal) for a, _ in script
    ]
    np.testing.assert_allclose(wps, np.array(ref))


def test_advance_matches_reference_on_random_walk():
    waypoints, edge_len, path = _scripted_path()
    subgoal = np.array([8.0, 0.0], np.float32)
    rng = np.random.default_rng(7)
    ag = np.cumsum(rng.normal(0.25, 0.3, (30, 2)), 0).astype(np.float32) * [1.0, 0.1]
    state, ref_state = P.follower_init(), {"idx": 0, "chase": 0}
    for a in ag.astype(np.float32):
        state, wp = advance(state, path, jnp.asarray(a), jnp.asarray(subgoal))
        ref = ref_get_waypoint(ref_state, waypoints, edge_len, a, subgoal)
        np.testing.assert_allclose(wp, ref)
        assert (int(state.index), int(state.chase_step)) == (ref_state["idx"], ref_state["chase"])
    assert ref_state["idx"] == 3  # the walk did finish the path


# --------------------------------------------------------------------------------------------
# Distance conversions
# --------------------------------------------------------------------------------------------


def test_pairwise_distance_in_row_blocks_matches_brute_force_and_bounds_memory():
    """Row blocks (the remainder included) give every pair; a 256-wide critic on 300 x 300
    landmarks for 4 vmapped seeds needs a fraction of one all-pairs activation (100 seeds in
    one call ran XLA's GPU autotuner out of memory: 17 GiB of operands)."""
    rng = np.random.default_rng(0)
    obs, goal = rng.normal(size=(37, 2)).astype(np.float32), rng.normal(size=(5, 2))
    brute = np.linalg.norm(obs[:, None, :] - goal[None, :, :].astype(np.float32), axis=-1)
    for rows in (1, 8, 37, 64):
        np.testing.assert_allclose(P.pairwise_distance(euclid, obs, goal, rows=rows), brute,
                                   rtol=1e-6)

    def critic(w, o, g):
        h = jax.nn.relu(jnp.concatenate([o, g], -1) @ w[0])
        return (jax.nn.relu(h @ w[1]) @ w[2])[..., 0]

    seeds, k, width = 4, 300, 256
    w = [jax.ShapeDtypeStruct((seeds, *s), jnp.float32)
         for s in ((4, width), (width, width), (width, 1))]
    pts = jax.ShapeDtypeStruct((seeds, k, 2), jnp.float32)

    def temp_bytes(rows: int) -> int:
        run = jax.jit(jax.vmap(lambda w, o, g: P.pairwise_distance(
            lambda a, b: critic(w, a, b), o, g, rows=rows)))
        return run.lower(w, pts, pts).compile().memory_analysis().temp_size_in_bytes

    one_activation = seeds * k * k * width * 4
    assert temp_bytes(k) > one_activation  # all pairs at once
    assert temp_bytes(P.PAIRWISE_ROWS) < one_activation / 3


def test_pairwise_distance():
    pairs = jax.jit(lambda o, g: P.pairwise_distance(euclid, o, g))(
        np.array([[0.0, 0.0], [3.0, 0.0]], np.float32),
        np.array([[0.0, 4.0], [3.0, 0.0], [0.0, 0.0]], np.float32),
    )
    np.testing.assert_allclose(pairs, [[4.0, 3.0, 0.0], [5.0, 0.0, 3.0]])
