"""True path lengths: the grid graph against its definition and scipy's Floyd-Warshall, and the
lengths against exact geodesics of the open room and the U-maze."""

import math

import jax
import jax.numpy as jnp
import numpy as np
from scipy.sparse.csgraph import shortest_path

from flrjax.envs import geodesic
from flrjax.envs.maze import U_MAZE, Maze, ROOM_24x8

#: The 16-neighbour grid's largest excess over a straight line, as a fraction of its length:
#: a direction halfway between two moves atan(1/2) apart.
ANISOTROPY = 1 / math.cos(math.atan(0.5) / 2) - 1


def _free_points(maze: Maze, n: int, seed: int) -> np.ndarray:
    lo, hi = maze.bounds
    rng = np.random.default_rng(seed)
    xy = rng.uniform(lo, hi, (8 * n, 2))
    return xy[np.asarray(maze.is_free(jnp.asarray(xy)))][:n]


def _blocked(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether segment a-b enters the open box (lo, hi) (Liang-Barsky clipping)."""
    t0, t1, d = 0.0, 1.0, b - a
    for k in range(2):
        if abs(d[k]) < 1e-12:
            if not lo[k] < a[k] < hi[k]:
                return False
            continue
        u, v = sorted(((lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]))
        t0, t1 = max(t0, u), min(t1, v)
        if t0 >= t1:
            return False
    return True


def _u_maze_exact(p: np.ndarray, q: np.ndarray) -> float:
    """The U-maze's exact geodesic: straight where the inner wall ([-4, 12] x [4, 12]) does
    not block, else round its two free corners (12, 4) and (12, 12)."""
    lo, hi = np.array([-4.0, 4.0]), np.array([12.0, 12.0])
    pts = [p, q, np.array([12.0, 4.0]), np.array([12.0, 12.0])]
    d = np.array([[np.linalg.norm(a - b) if not _blocked(a, b, lo, hi) else np.inf
                   for b in pts] for a in pts])
    for m in range(4):
        d = np.minimum(d, d[:, m, None] + d[None, m, :])
    return d[0, 1]


def test_grid_graph_is_the_free_moves_and_its_table_is_all_pairs_shortest_paths():
    """At two squares per cell: every edge is a move of MOVES whose bounding box is free, with
    its length; the table equals scipy's Floyd-Warshall on a graph rebuilt here from that
    definition."""
    maze = Maze(U_MAZE)
    wall = geodesic.grid(maze, 2)
    free, adj = geodesic.graph(wall, size=4.0)
    rows, cols = wall.shape
    index = {tuple(c): n for n, c in enumerate(free)}
    want = np.full((len(free), len(free)), np.inf)
    for (i, j), a in index.items():
        for di in range(-2, 3):
            for dj in range(-2, 3):
                if (abs(di), abs(dj)) not in {(0, 1), (1, 0), (1, 1), (1, 2), (2, 1)}:
                    continue
                box = wall[max(0, min(i, i + di)):max(i, i + di) + 1,
                           max(0, min(j, j + dj)):max(j, j + dj) + 1]
                inside = 0 <= i + di < rows and 0 <= j + dj < cols
                if inside and (i + di, j + dj) in index and not box.any():
                    want[a, index[(i + di, j + dj)]] = 4.0 * math.hypot(di, dj)
    got = adj.toarray()
    got[got == 0] = np.inf
    np.testing.assert_allclose(got, want)
    geo = geodesic.table(maze, 2)
    assert geo.size == 4.0
    np.testing.assert_allclose(geo.dist, shortest_path(np.where(np.isinf(want), 0, want),
                                                       method="FW", directed=False), rtol=1e-6)


def test_one_square_per_cell_walks_the_u_from_cell_to_cell():
    """One square per cell: the knight's and diagonal moves all touch the inner wall, so start
    to goal is the six cell steps round the U."""
    maze = Maze(U_MAZE)
    geo = geodesic.table(maze, 1)
    assert float(geodesic.distance(geo, maze.start, maze.goal)) == 6 * maze.scale


def test_open_room_is_the_straight_line_within_grid_error():
    maze = Maze(ROOM_24x8)
    geo = geodesic.table(maze)
    p, q = _free_points(maze, 300, 0), _free_points(maze, 300, 1)
    straight = np.linalg.norm(p - q, axis=-1)
    got = np.asarray(geodesic.distance(geo, jnp.asarray(p), jnp.asarray(q)))
    # snapping moves each end by at most half a square's diagonal
    np.testing.assert_array_less(np.abs(got - straight),
                                 ANISOTROPY * straight + math.sqrt(2) * geo.size + 1e-4)


def test_u_maze_goes_round_the_inner_wall_like_the_exact_geodesic():
    """Random free pairs against the exact geodesic, within the grid's error (anisotropy, the
    snapped ends, and half a square off each corner the path turns round); start to goal runs
    up one arm and down the other, two points in one arm are the straight line."""
    maze = Maze(U_MAZE)
    geo = geodesic.table(maze)
    p, q = _free_points(maze, 300, 2), _free_points(maze, 300, 3)
    exact = np.array([_u_maze_exact(a, b) for a, b in zip(p, q, strict=True)])
    got = np.asarray(geodesic.distance(geo, jnp.asarray(p), jnp.asarray(q)))
    np.testing.assert_array_less(np.abs(got - exact),
                                 ANISOTROPY * exact + 3 * geo.size + 1e-4)
    round_the_u = 2 * math.hypot(12, 4) + 8
    assert abs(float(geodesic.distance(geo, maze.start, maze.goal)) - round_the_u) < (
        ANISOTROPY * round_the_u + 3 * geo.size)
    assert float(geodesic.distance(geo, maze.start, maze.goal)) > 1.9 * 16  # not across
    arm = float(geodesic.distance(geo, jnp.array([-2.5, 0.5]), jnp.array([10.5, 0.5])))
    assert arm == 13.0


def test_lookups_jit_and_snap_points_in_walls_to_the_nearest_free_square():
    maze = Maze(U_MAZE)
    geo = geodesic.table(maze)
    dist = jax.jit(jax.vmap(lambda a, b: geodesic.distance(geo, a, b)))
    p = jnp.array([[4.0, 8.0], [0.5, 0.5], [-50.0, 0.5]])  # in the wall; free; beyond the edge
    q = jnp.array([[4.5, 12.5], [0.5, 0.5], [-3.5, 0.5]])
    np.testing.assert_allclose(dist(p, q), [0.0, 0.0, 0.0])
    np.testing.assert_allclose(geo.dist, geo.dist.T)


def test_a_large_maze_gets_fewer_squares_per_cell():
    layout = ("#" * 22, "#S" + "." * 19 + "#", *["#" + "." * 20 + "#"] * 18,
              "#" + "." * 19 + "G#", "#" * 22)
    geo = geodesic.table(Maze(layout))
    assert geo.dist.shape[0] <= geodesic.MAX_NODES and geo.size > Maze(layout).scale / 8
