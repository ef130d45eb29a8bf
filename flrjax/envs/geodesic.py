"""True path lengths in a maze: the shortest obstacle-free distance between two points.

The learned distance critics and the high level's subgoals are judged against what the maze
itself says (:mod:`flrjax.algos.hierarchy`'s ``stats/`` metrics): how far apart two points are
for a body that must walk around the walls. The free space is cut into a grid of
``per_cell`` x ``per_cell`` squares per maze cell; each free square is a node, joined to its
16 neighbours (the 8 adjacent squares and the 8 knight's moves) by its straight-line length
where every square of the move's bounding box is free, so that no move cuts a wall's corner.
:func:`table` runs Dijkstra from every node once (``scipy.sparse.csgraph``) and keeps the
all-pairs table; :func:`distance` snaps both points to their nearest free square and reads
the table, a gather that jit, vmap and scan take.

Resolution: one world unit per square on the paper's mazes (8 squares per 8-unit cell). A
straight line through the 16-neighbour grid is longer than the true one by at most
``1 / cos(atan(1/2) / 2) - 1`` of its length, and snapping moves each end by at most half a
square's diagonal: both small against a cell, the success radius and the reach threshold.
Finer grids grow the table with the square of the nodes, so a large maze gets fewer squares
per cell (:data:`MAX_NODES`).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from flrjax.envs.maze import Maze

#: Squares per maze cell along each axis, unless the table would exceed :data:`MAX_NODES`.
PER_CELL = 8
#: Most free squares of a table (its memory is ``4 * MAX_NODES**2`` bytes).
MAX_NODES = 2048
#: Moves of the grid graph (one of each +- pair): the 8 adjacent squares and the knight's.
MOVES = ((0, 1), (1, 0), (1, 1), (1, -1), (1, 2), (2, 1), (1, -2), (2, -1))


@struct.dataclass
class Geodesic:
    """A maze's all-pairs true path lengths on its grid of squares (world units)."""

    dist: np.ndarray  # [N, N] float32 shortest path between free squares' centres
    snap: np.ndarray  # [rows, cols] int32: nearest free square of each square (itself if free)
    origin: np.ndarray  # [2] world (x, y) of the grid's lower-left corner
    size: float = struct.field(pytree_node=False)  # a square's side


def grid(maze: Maze, per_cell: int) -> np.ndarray:
    """Boolean ``[rows * per_cell, cols * per_cell]``: True where a square is wall."""
    return np.kron(maze.grid, np.ones((per_cell, per_cell), bool))


def graph(wall: np.ndarray, size: float = 1.0) -> tuple[np.ndarray, coo_matrix]:
    """The grid graph of the free squares: their ``[N, 2]`` (row, col) and the ``[N, N]``
    sparse matrix of the moves (:data:`MOVES`, both ways) whose bounding box is free, weighted
    by their length in world units."""
    free = np.argwhere(~wall)
    node = np.full(wall.shape, -1)
    node[tuple(free.T)] = np.arange(len(free))
    rows, cols = wall.shape
    src, dst, w = [], [], []
    for di, dj in MOVES:
        i2, j2 = free[:, 0] + di, free[:, 1] + dj
        inside = (i2 >= 0) & (i2 < rows) & (j2 >= 0) & (j2 < cols)
        ok = inside.copy()
        for a in range(min(0, di), max(0, di) + 1):  # every square of the move's box is free
            for b in range(min(0, dj), max(0, dj) + 1):
                ii, jj = free[:, 0] + a, free[:, 1] + b
                box_in = (ii >= 0) & (ii < rows) & (jj >= 0) & (jj < cols)
                ok &= box_in & ~wall[np.clip(ii, 0, rows - 1), np.clip(jj, 0, cols - 1)]
        s = np.flatnonzero(ok)
        d = node[i2[ok], j2[ok]]
        src += [s, d]
        dst += [d, s]
        w += [np.full(2 * len(s), size * math.hypot(di, dj))]
    src, dst, w = (np.concatenate(x) for x in (src, dst, w))
    return free, coo_matrix((w, (src, dst)), shape=(len(free), len(free)))


@functools.lru_cache(maxsize=8)
def table(maze: Maze, per_cell: int = PER_CELL) -> Geodesic:
    """The maze's :class:`Geodesic` at ``per_cell`` squares per cell (fewer where more would
    exceed :data:`MAX_NODES` free squares); computed once per maze and kept."""
    n_free = int((~maze.grid).sum())
    per_cell = max(1, min(per_cell, math.isqrt(MAX_NODES // n_free)))
    wall = grid(maze, per_cell)
    size = maze.scale / per_cell
    free, adjacency = graph(wall, size)
    dist = dijkstra(adjacency.tocsr(), directed=False)
    # nearest free square of every square, by the distance between their centres
    _, (ni, nj) = distance_transform_edt(wall, return_indices=True)
    node = np.full(wall.shape, -1, np.int32)
    node[tuple(free.T)] = np.arange(len(free))
    # cell (0, 0)'s lower-left corner: its centre is maze.cell_center(0, 0)
    origin = maze.cell_center(0, 0) - maze.scale / 2
    return Geodesic(dist=dist.astype(np.float32), snap=node[ni, nj],
                    origin=origin.astype(np.float32), size=float(size))


def node(geo: Geodesic, xy: jax.Array) -> jax.Array:
    """The free square nearest each point ``xy[..., 2]`` (world x, y): an index into
    ``geo.dist``. Points outside the grid count as on its border."""
    rows, cols = geo.snap.shape
    ij = jnp.floor((xy - geo.origin) / geo.size).astype(jnp.int32)
    j = jnp.clip(ij[..., 0], 0, cols - 1)
    i = jnp.clip(ij[..., 1], 0, rows - 1)
    return jnp.asarray(geo.snap)[i, j]


def distance(geo: Geodesic, p: jax.Array, q: jax.Array) -> jax.Array:
    """True path length from ``p[..., 2]`` to ``q[..., 2]`` (broadcast), in world units."""
    return jnp.asarray(geo.dist)[node(geo, p), node(geo, q)]
