"""DHRL graph planner as pure, jit/vmap-able JAX functions.

DHRL (Lee et al., 2022) plans over a graph of *landmarks* (achieved goals picked from the
low-level replay) whose edge weights are the low-level critic's estimate of the number of steps
between them. For each new *subgoal* from the high level it finds a shortest path from the
current state through the landmarks to the subgoal and feeds the landmarks on it to the low
level as *waypoints*, one at a time.

Everything here has static shapes: at most ``max_nodes`` landmarks with a validity mask, paths
of at most ``max_path_len`` waypoints with a length, ``inf`` for "no edge" / "unreachable".
No Python loop runs over data, so the functions run inside a jitted, ``lax.scan``-ned,
seed-``vmap``-ped training step.

Reference: github.com/jayLEE0301/dhrl_official (cited below as ``graph.py`` =
``DHRL/rl/algo/graph.py``, ``agent.py`` = ``DHRL/rl/agent/agent.py``, ``dhrl.py`` =
``DHRL/rl/algo/dhrl.py``, ``replay/planner.py`` = ``DHRL/rl/replay/planner.py``, ``main.py`` =
``DHRL/main.py``, ``AntMaze.sh`` = ``scripts/AntMaze.sh``).

Typical use (``follower = follower_init()`` with each new path)::

    graph = graph_construct(key, dist_fn, obs_batch, ag_batch, valid)       # every rebuild
    path = find_path(graph, dist_fn, obs, subgoal)                           # new subgoal
    follower, waypoint = advance(follower, path, achieved_goal, subgoal)     # every step
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array
DistFn = Callable[[Array, Array], Array]
"""``dist_fn(obs[B, ...], goal[B, g]) -> [B]``: estimated steps from ``obs`` to reach ``goal``."""

# Defaults of the reference AntMaze run (main.py argparse defaults == AntMaze.sh flags).
INITIAL_SAMPLE = 6000  # main.py --initial_sample: states sampled per graph build
N_GRAPH_NODE = 300  # main.py / AntMaze.sh --n_graph_node: max landmarks
LOW_BOUND_EPSILON = 10.0  # main.py / AntMaze.sh --low_bound_epsilon: FPS early-stop distance
CUTOFF = 30.0  # main.py / AntMaze.sh --cutoff: max edge length (steps)
NN_FACTOR = 1.2  # graph.py graph_construct: also keep edges < 1.2 x i's nearest neighbour
START_FALLBACK_FACTOR = 1.5  # graph.py find_path: start edges < 1.5 x nearest if none < cutoff
REACH_EPS = 0.5  # graph.py get_waypoint: waypoint counts as reached within 0.5


# --- Pairwise critic distances (agent.py _get_pairwise_dist) --------------------------------


#: Rows of a pairwise distance matrix evaluated per critic call: 32 x 300 landmarks keep a
#: 256-wide layer's float32 activations at 32 * 300 * 256 * 4 B = 10 MB per seed, against
#: 92 MB for all 300 x 300 pairs at once, times the vmapped seeds.
PAIRWISE_ROWS = 32


def pairwise_distance(dist_fn: DistFn, obs: Array, goal: Array,
                      rows: int = PAIRWISE_ROWS) -> Array:
    """``D[i, j] = dist_fn(obs[i], goal[j])`` for ``obs[n, ...]``, ``goal[m, g]``.

    ``rows`` rows of pairs per call (agent.py ``_get_pairwise_dist`` loops over single rows),
    so memory does not grow with n*m; ``D[i, j]`` is the distance *from* i *to* j.
    """
    m = goal.shape[0]
    return jax.lax.map(lambda o: dist_fn(_broadcast_row(o, m), goal), obs,
                       batch_size=min(rows, obs.shape[0]))


def _broadcast_row(x: Array, n: int) -> Array:
    return jnp.broadcast_to(x, (n, *x.shape))


# --- Landmarks: farthest-point sampling (graph.py fps_selection) ----------------------------


@struct.dataclass
class Landmarks:
    """Fixed-size landmark set picked from a batch of replay samples.

    ``index[k]`` indexes the sampled batch, ``state`` is the full observation (edge *source*),
    ``goal`` the achieved goal (edge *target* and the waypoint the low level chases), as in
    graph.py ``graph_construct`` (``self.states`` / ``self.landmarks``).
    """

    index: Array  # [K] int32
    state: Array  # [K, obs_dim]
    goal: Array  # [K, goal_dim]
    mask: Array  # [K] bool, False for unused slots


def _start_index(key_or_start: Array | int, valid: Array) -> Array:
    """First FPS point: an explicit index, or uniform over ``valid`` states for a PRNG key."""
    if isinstance(key_or_start, int):
        return jnp.asarray(key_or_start, jnp.int32)
    x = jnp.asarray(key_or_start)
    is_typed_key = jnp.issubdtype(x.dtype, jax.dtypes.prng_key)
    if is_typed_key or (x.shape == (2,) and x.dtype == jnp.uint32):
        logits = jnp.where(valid, 0.0, -jnp.inf)
        return jax.random.categorical(x, logits).astype(jnp.int32)
    if x.ndim == 0 and jnp.issubdtype(x.dtype, jnp.integer):
        return x.astype(jnp.int32)
    raise TypeError(f"key_or_start must be a PRNG key or an integer index, got {x.dtype}{x.shape}")


def farthest_point_sampling(
    key_or_start: Array | int,
    dist_fn_or_matrix: DistFn | Array,
    states: Array,
    goals: Array | None = None,
    *,
    max_nodes: int = N_GRAPH_NODE,
    stop_eps: float = LOW_BOUND_EPSILON,
    min_nodes: int | None = None,
    valid: Array | None = None,
) -> Landmarks:
    """Pick up to ``max_nodes`` landmarks by farthest-point sampling (graph.py fps_selection).

    Keeps ``cover[x] = min over chosen c of d(state_c -> goal_x)`` and repeatedly picks
    ``argmax cover``. As in the reference the distance is directed, *from* the landmark, and
    the chosen point's own distance is set to 0. Early stop (masked): once
    ``max(cover) < stop_eps`` *and* more than ``min_nodes`` (default ``max_nodes // 10``,
    the reference's ``len(chosen) > n_graph_node / 10``) were chosen, no further slot is valid.

    ``dist_fn_or_matrix``: a ``DistFn`` (one batched call of N pairs per iteration, the
    reference's cost) or a precomputed ``[N, N]`` matrix ``M[i, x] = d(state_i -> goal_x)``.
    ``key_or_start``: a PRNG key (random valid start) or an int index. The reference starts at
    index 0 of a random replay batch (``argmax`` of an all-``1e6`` array), i.e. ``0`` here.
    ``valid[N]`` masks unfilled replay slots; they are never chosen.
    """
    states = jnp.asarray(states)
    goals = states if goals is None else jnp.asarray(goals)
    n = states.shape[0]
    valid = jnp.ones((n,), bool) if valid is None else jnp.asarray(valid)
    min_nodes = max_nodes // 10 if min_nodes is None else min_nodes
    start = _start_index(key_or_start, valid)

    if callable(dist_fn_or_matrix):
        dist_fn = dist_fn_or_matrix

        def row(i: Array) -> Array:
            return dist_fn(_broadcast_row(states[i], n), goals)
    else:
        matrix = jnp.asarray(dist_fn_or_matrix)

        def row(i: Array) -> Array:
            return matrix[i]

    def step(carry, t):
        cover, stopped = carry
        masked_cover = jnp.where(valid, cover, -jnp.inf)
        stopped = stopped | ((jnp.max(masked_cover) < stop_eps) & (t > min_nodes))
        idx = jnp.where(t == 0, start, jnp.argmax(masked_cover)).astype(jnp.int32)
        new = row(idx).astype(cover.dtype).at[idx].set(0.0)
        cover = jnp.where(stopped, cover, jnp.minimum(cover, new))
        return (cover, stopped), (idx, ~stopped & valid[idx])

    cover0 = jnp.full((n,), jnp.inf, jnp.result_type(float))
    _, (index, mask) = jax.lax.scan(step, (cover0, jnp.asarray(False)), jnp.arange(max_nodes))
    return Landmarks(index=index, state=states[index], goal=goals[index], mask=mask)


# --- Graph: edges (graph.py graph_construct) and all-pairs shortest paths -------------------


@struct.dataclass
class Graph:
    """Landmark graph with its all-pairs shortest paths (``inf`` = no edge / unreachable)."""

    landmarks: Landmarks
    weight: Array  # [K, K] edge i->j weight, inf where no edge
    dist: Array  # [K, K] shortest-path length i->j
    next_hop: Array  # [K, K] int32, first node after i on a shortest path to j; -1 if none


def edge_weights(pdist: Array, mask: Array, *, cutoff: float = CUTOFF,
                 nn_factor: float = NN_FACTOR) -> Array:
    """Edge weights from a landmark distance matrix (graph.py graph_construct).

    Edge i->j (weight ``pdist[i, j]``) iff ``pdist[i, j] < cutoff`` or
    ``pdist[i, j] < nn_factor * min_{k != i} pdist[i, k]``: the second rule keeps each
    landmark connected to its nearest neighbours even when all of them are beyond the cutoff.
    Only valid landmarks take part (the reference's graph has no invalid nodes).
    """
    k = pdist.shape[0]
    pair = mask[:, None] & mask[None, :]
    off_diag = ~jnp.eye(k, dtype=bool)
    nearest = jnp.min(jnp.where(pair & off_diag, pdist, jnp.inf), axis=1, keepdims=True)
    edge = pair & ((pdist < cutoff) | (pdist < nn_factor * nearest))
    return jnp.where(edge, pdist, jnp.inf)


def all_pairs_shortest_paths(weight: Array) -> tuple[Array, Array]:
    """Floyd-Warshall as a ``fori_loop`` of min-plus updates: ``(dist, next_hop)``.

    ``weight[i, j]`` is the edge i->j (``inf`` = none; assumed without negative cycles).
    ``dist[i, i] = 0``; ``next_hop[i, j]`` is the node after i on a shortest i->j path
    (``i`` itself when ``i == j``, -1 when j is unreachable). O(K^3) work, K sequential steps.
    """
    k = weight.shape[0]
    eye = jnp.eye(k, dtype=bool)
    dist = jnp.where(eye, jnp.minimum(jnp.diagonal(weight), 0.0)[:, None], weight)
    cols = jnp.broadcast_to(jnp.arange(k, dtype=jnp.int32)[None, :], (k, k))
    next_hop = jnp.where(eye | jnp.isfinite(dist), cols, -1)

    def relax(m, carry):
        dist, next_hop = carry
        via = dist[:, m, None] + dist[None, m, :]
        better = via < dist
        return jnp.where(better, via, dist), jnp.where(better, next_hop[:, m, None], next_hop)

    return jax.lax.fori_loop(0, k, relax, (dist, next_hop))


def graph_from_distances(landmarks: Landmarks, pdist: Array, *, cutoff: float = CUTOFF,
                         nn_factor: float = NN_FACTOR) -> Graph:
    """Graph from landmarks and their distance matrix ``pdist[i, j] = d(state_i -> goal_j)``."""
    weight = edge_weights(pdist, landmarks.mask, cutoff=cutoff, nn_factor=nn_factor)
    dist, next_hop = all_pairs_shortest_paths(weight)
    return Graph(landmarks=landmarks, weight=weight, dist=dist, next_hop=next_hop)


def graph_with_distances(
    key_or_start: Array | int,
    dist_fn: DistFn,
    states: Array,
    goals: Array,
    valid: Array | None = None,
    *,
    max_nodes: int = N_GRAPH_NODE,
    stop_eps: float = LOW_BOUND_EPSILON,
    cutoff: float = CUTOFF,
    nn_factor: float = NN_FACTOR,
) -> tuple[Graph, Array]:
    """Full rebuild (graph.py graph_construct): FPS landmarks, pairwise distances, APSP; the
    graph and the landmarks' distance matrix ``pdist[i, j] = d(state_i -> goal_j)`` it was
    built from (every pair's estimate, before the cutoff, for judging them against the true
    ones).

    ``states[N, obs_dim]`` / ``goals[N, g]``: observations and achieved goals of N (6000 in the
    reference, main.py ``--initial_sample``) transitions sampled from the low-level replay.
    """
    landmarks = farthest_point_sampling(
        key_or_start, dist_fn, states, goals, max_nodes=max_nodes, stop_eps=stop_eps, valid=valid
    )
    pdist = pairwise_distance(dist_fn, landmarks.state, landmarks.goal)
    return graph_from_distances(landmarks, pdist, cutoff=cutoff, nn_factor=nn_factor), pdist


def graph_construct(*args, **kwargs) -> Graph:
    """:func:`graph_with_distances`'s graph alone."""
    return graph_with_distances(*args, **kwargs)[0]


def empty_graph(max_nodes: int, obs_dim: int, goal_dim: int,
                dtype: jnp.dtype = jnp.float32) -> Graph:
    """A graph with no valid landmark: plans on it are empty, so waypoint == subgoal.

    Stands in for the reference's ``graph is None`` before the first build
    (dhrl.py ``run``: the graph is built only after ``start_planning_epoch``).
    """
    k = max_nodes
    landmarks = Landmarks(
        index=jnp.zeros((k,), jnp.int32),
        state=jnp.zeros((k, obs_dim), dtype),
        goal=jnp.zeros((k, goal_dim), dtype),
        mask=jnp.zeros((k,), bool),
    )
    eye = jnp.eye(k, dtype=bool)
    weight = jnp.full((k, k), jnp.inf, dtype)
    dist = jnp.where(eye, 0.0, weight)  # == all_pairs_shortest_paths(weight), without the loop
    next_hop = jnp.where(eye, jnp.arange(k, dtype=jnp.int32)[None, :], -1)
    return Graph(landmarks=landmarks, weight=weight, dist=dist, next_hop=next_hop)


def graph_to_goal_distance(graph: Graph, goal_dist: Array) -> Array:
    """``min`` over valid landmarks of ``d(landmark -> goal)`` (graph.py dist_from_graph_to_goal).

    The reference penalises high-level subgoals farther than ``3 * cutoff`` from the graph
    (replay/planner.py ``sample_her_transitions_with_subgoaltesting``).
    """
    return jnp.min(jnp.where(graph.landmarks.mask, goal_dist, jnp.inf), axis=-1)


# --- Planning for one (start, subgoal) pair (graph.py find_path) ----------------------------


@struct.dataclass
class Path:
    """Waypoints from the current state towards a subgoal, padded to ``max_path_len``.

    ``edge_len[k]`` is the estimated length of the edge *into* waypoint k (graph.py
    ``edge_lengths``); the follower gives up on waypoint k after that many steps. A path longer
    than ``L`` is cut to its first ``L`` waypoints (``truncated``); after them the follower
    heads for the subgoal, as it does after the last waypoint of a complete path.
    """

    landmark: Array  # [L] int32 landmark ids on the path, -1 padded
    waypoint: Array  # [L, goal_dim] their goal coordinates, 0 padded
    edge_len: Array  # [L] float, 0 padded
    length: Array  # int32 number of waypoints (0: chase the subgoal directly)
    reaches_subgoal: Array  # bool; False: subgoal unreachable, path ends at nearest landmark
    cost: Array  # float, estimated steps start -> subgoal along the plan (inf: no plan)
    truncated: Array  # bool, the path had more than L waypoints; only the first L are kept


def shortest_path(
    graph: Graph,
    start_dist: Array,
    goal_dist: Array,
    start_goal_dist: Array | float = jnp.inf,
    *,
    cutoff: float = CUTOFF,
    max_path_len: int = 32,
    start_factor: float = START_FALLBACK_FACTOR,
) -> Path:
    """Shortest start -> landmarks -> subgoal path, with the reference's fallbacks.

    Inputs: ``start_dist[K] = d(start -> goal_i)``, ``goal_dist[K] = d(state_i -> subgoal)``,
    ``start_goal_dist = d(start -> subgoal)``. graph.py find_path:

    1. edges start->i, i->subgoal and start->subgoal exist where the distance is < ``cutoff``;
    2. if start has no edge at all, add start->i for every i with
       ``start_dist[i] < start_factor * min(start_dist)``;
    3. if the subgoal is reachable, take the shortest path (a direct start->subgoal edge gives
       no waypoint);
    4. otherwise go to the landmark *reachable from start* with the smallest ``goal_dist``
       (the reference's loop over ``argmin(goal_edge_length)``), then to the subgoal.

    Returns the landmarks on the path (excluding start and subgoal) as waypoints.
    """
    graph = jax.tree.map(jnp.asarray, graph)
    lm = graph.landmarks
    inf = jnp.inf
    start_dist = jnp.where(lm.mask, start_dist, inf)
    goal_dist = jnp.where(lm.mask, goal_dist, inf)
    start_goal_dist = jnp.asarray(start_goal_dist, start_dist.dtype)

    s = jnp.where(start_dist < cutoff, start_dist, inf)  # start -> i
    t = jnp.where(goal_dist < cutoff, goal_dist, inf)  # i -> subgoal
    direct = jnp.where(start_goal_dist < cutoff, start_goal_dist, inf)
    has_start = jnp.any(jnp.isfinite(s)) | jnp.isfinite(direct)
    fallback_s = jnp.where(start_dist < start_factor * jnp.min(start_dist), start_dist, inf)
    s = jnp.where(has_start, s, fallback_s)

    reach = jnp.min(s[:, None] + graph.dist, axis=0)  # start -> j through the landmarks
    via_cost = reach + t
    j_goal = jnp.argmin(via_cost)
    found = jnp.isfinite(jnp.minimum(via_cost[j_goal], direct))
    use_direct = found & (direct <= via_cost[j_goal])

    reachable = jnp.isfinite(reach)
    j_near = jnp.argmin(jnp.where(reachable, goal_dist, inf))
    target = jnp.where(found, j_goal, j_near).astype(jnp.int32)
    has_path = jnp.where(found, ~use_direct, jnp.any(reachable))
    entry = jnp.argmin(s + graph.dist[:, target]).astype(jnp.int32)
    last_edge = jnp.where(found, t[target], goal_dist[target])
    cost = jnp.where(use_direct, direct, jnp.where(has_path, reach[target] + last_edge, inf))

    def walk(carry, _):
        node, done = carry
        out = jnp.where(done, -1, node)
        nxt = graph.next_hop[node, target]
        done = done | (node == target) | (nxt < 0)
        return (jnp.where(done, node, nxt), done), out

    _, nodes = jax.lax.scan(walk, (entry, ~has_path), None, length=max_path_len)
    on_path = nodes >= 0
    safe = jnp.maximum(nodes, 0)
    prev = jnp.concatenate([entry[None], safe[:-1]])
    inner = graph.weight[prev, safe]
    edge_len = jnp.where(jnp.arange(max_path_len) == 0, s[entry], inner)
    return Path(
        landmark=nodes,
        waypoint=jnp.where(on_path[:, None], lm.goal[safe], 0.0),
        edge_len=jnp.where(on_path, edge_len, 0.0),
        length=jnp.sum(on_path).astype(jnp.int32),
        reaches_subgoal=found,
        cost=cost,
        truncated=has_path & ~jnp.any(nodes == target),
    )


def find_path(
    graph: Graph,
    dist_fn: DistFn,
    obs: Array,
    subgoal: Array,
    *,
    cutoff: float = CUTOFF,
    max_path_len: int = 32,
    start_factor: float = START_FALLBACK_FACTOR,
) -> Path:
    """Plan from ``obs[obs_dim]`` to ``subgoal[goal_dim]``; the 2K+1 distances in one call."""
    lm = graph.landmarks
    k = lm.goal.shape[0]
    obs_b = jnp.concatenate([_broadcast_row(obs, k), lm.state, obs[None]], axis=0)
    goal_b = jnp.concatenate([lm.goal, _broadcast_row(subgoal, k), subgoal[None]], axis=0)
    d = dist_fn(obs_b, goal_b)
    return shortest_path(
        graph,
        d[:k],
        d[k : 2 * k],
        d[2 * k],
        cutoff=cutoff,
        max_path_len=max_path_len,
        start_factor=start_factor,
    )


# --- Waypoint follower (graph.py get_waypoint) ----------------------------------------------


@struct.dataclass
class FollowerState:
    """Which waypoint of the current path the low level chases, and for how long."""

    index: Array  # int32 index into Path.landmark; >= Path.length: chase the subgoal
    chase_step: Array  # int32 steps spent on the current waypoint


def follower_init() -> FollowerState:
    """Fresh follower, set whenever a new path is planned (graph.py find_path end)."""
    return FollowerState(index=jnp.asarray(0, jnp.int32), chase_step=jnp.asarray(0, jnp.int32))


def advance(
    state: FollowerState,
    path: Path,
    achieved_goal: Array,
    subgoal: Array,
    *,
    reach_eps: float = REACH_EPS,
) -> tuple[FollowerState, Array]:
    """One env step of waypoint following: ``(new_state, waypoint to condition the low level)``.

    graph.py get_waypoint, called every step including the one that planned: count the step,
    then move to the next waypoint if ``chase_step > edge_len[index]`` or the achieved goal is
    within ``reach_eps`` of the current waypoint (at most one switch per step, and the chase
    counter restarts at 0). Past the last waypoint the low level chases the subgoal itself.
    """
    path = jax.tree.map(jnp.asarray, path)
    last = path.landmark.shape[0] - 1
    chase = state.chase_step + 1
    cur = jnp.clip(state.index, 0, last)
    near = jnp.linalg.norm(achieved_goal - path.waypoint[cur]) < reach_eps
    switch = (state.index < path.length) & ((chase > path.edge_len[cur]) | near)
    index = state.index + switch.astype(jnp.int32)
    chase = jnp.where(switch, 0, chase).astype(jnp.int32)
    waypoint = jnp.where(index < path.length, path.waypoint[jnp.clip(index, 0, last)], subgoal)
    return FollowerState(index=index, chase_step=chase), waypoint
