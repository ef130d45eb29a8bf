"""Maze layouts: a grid of cells, its walls as few boxes, and goal sampling in free space.

A layout is a tuple of strings, one per row: ``#`` wall, ``.`` free, ``S`` start, ``G`` goal.
Row 0 is the *lowest* y (rows grow with y, as in the rllab/HIRO ``construct_maze`` structure
that jayLEE0301/dhrl_official ``envs/antenv/maze_env.py`` places at ``(j * scale, i * scale)``).
World coordinates are shifted so that the centre of the ``S`` cell is the origin, again as the
reference does (``_find_robot`` and the offset by ``torso_x, torso_y``).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

# jayLEE0301/dhrl_official envs/antenv/maze_env_utils.py, construct_maze('Maze'):
# [[1,1,1,1,1],[1,r,0,0,1],[1,1,1,0,1],[1,g,0,0,1],[1,1,1,1,1]], row index = y.
U_MAZE = (
    "#####",
    "#S..#",
    "###.#",
    "#G..#",
    "#####",
)

# Paper §3.1: "3-legged ant starts at the left in 24 x 8 room, and targets to the right".
# Three free cells of 8 x 8 in a row: 24 x 8 world units, start left, goal right.
ROOM_24x8 = (
    "#####",
    "#S.G#",
    "#####",
)


@dataclasses.dataclass(frozen=True)
class Maze:
    """A maze layout placed in the world: ``scale`` world units per cell."""

    layout: tuple[str, ...]
    scale: float = 8.0  # maze_size_scaling 8: dhrl_official envs/antenv/create_maze_env.py
    height: float = 0.5  # maze_height 0.5 (in cells): dhrl_official envs/antenv/maze_env.py

    def __post_init__(self) -> None:
        widths = {len(r) for r in self.layout}
        if len(widths) != 1:
            raise ValueError(f"maze rows must have equal length, got lengths {sorted(widths)}")
        chars = set("".join(self.layout))
        if not chars <= set("#.SG"):
            raise ValueError(f"maze layout may only use '#', '.', 'S', 'G'; got {sorted(chars)}")
        for c in "SG":
            if "".join(self.layout).count(c) != 1:
                raise ValueError(f"maze layout needs exactly one '{c}'")

    @property
    def grid(self) -> np.ndarray:
        """Boolean ``[rows, cols]`` array, True where a wall is."""
        return np.array([[ch == "#" for ch in row] for row in self.layout])

    def _find(self, ch: str) -> tuple[int, int]:
        for i, row in enumerate(self.layout):
            if ch in row:
                return i, row.index(ch)
        raise AssertionError(ch)

    def cell_center(self, i: int, j: int) -> np.ndarray:
        """World (x, y) of the centre of cell (row i, column j)."""
        si, sj = self._find("S")
        return np.array([(j - sj) * self.scale, (i - si) * self.scale], dtype=np.float32)

    @property
    def start(self) -> np.ndarray:
        return self.cell_center(*self._find("S"))

    @property
    def goal(self) -> np.ndarray:
        return self.cell_center(*self._find("G"))

    @property
    def free_cells(self) -> np.ndarray:
        """``[n_free, 2]`` world centres of all non-wall cells."""
        rows, cols = np.nonzero(~self.grid)
        return np.stack([self.cell_center(i, j) for i, j in zip(rows, cols, strict=True)])

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) corners of the bounding box of the free space."""
        c = self.free_cells
        return c.min(0) - self.scale / 2, c.max(0) + self.scale / 2

    def wall_boxes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Walls merged greedily into few axis-aligned boxes: ``[(centre_xy, half_size_xy)]``.

        Each box costs one collision pair per colliding ant geom in MJX, so runs of wall
        cells become one box (the U-maze's 17 wall cells become 5 boxes).
        """
        wall = self.grid.copy()
        rows, cols = wall.shape
        boxes = []
        for i in range(rows):
            for j in range(cols):
                if not wall[i, j]:
                    continue
                j2 = j
                while j2 + 1 < cols and wall[i, j2 + 1]:
                    j2 += 1
                i2 = i
                while i2 + 1 < rows and wall[i2 + 1, j : j2 + 1].all():
                    i2 += 1
                wall[i : i2 + 1, j : j2 + 1] = False
                lo = self.cell_center(i, j) - self.scale / 2
                hi = self.cell_center(i2, j2) + self.scale / 2
                boxes.append(((lo + hi) / 2, (hi - lo) / 2))
        return boxes

    def outer_walls(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The four faces of the free space's bounding box as ``(point_xy, inward_normal_xy)``.

        Everything beyond them is wall, so in the physics they can be half-spaces (MJCF planes,
        whose collisions are analytic and cheap) instead of boxes.
        """
        lo, hi = self.bounds
        return [(np.array([lo[0], 0.0]), np.array([1.0, 0.0])),
                (np.array([hi[0], 0.0]), np.array([-1.0, 0.0])),
                (np.array([0.0, lo[1]]), np.array([0.0, 1.0])),
                (np.array([0.0, hi[1]]), np.array([0.0, -1.0]))]

    def split_wall_boxes(self) -> tuple[list, list]:
        """``wall_boxes()`` split into (inside the free space's bounding box, the rest): the
        U-maze has one inner box, the room none; the rest lies behind :meth:`outer_walls`."""
        lo, hi = self.bounds
        inner, outer = [], []
        for c, h in self.wall_boxes():
            is_inner = np.all(c - h >= lo - 1e-6) and np.all(c + h <= hi + 1e-6)
            (inner if is_inner else outer).append((c, h))
        return inner, outer

    def sample_goal(self, key: jax.Array) -> jax.Array:
        """A goal uniform over the free area (a uniform free cell, then uniform in it).

        For the U-maze this is the reference's ``rand_goal``: uniform on [-4, 20]^2 minus the
        inner wall (dhrl_official envs/antenv/__init__.py, EnvWithGoal.rand_goal).
        """
        cells = jnp.asarray(self.free_cells)
        k_cell, k_off = jax.random.split(key)
        idx = jax.random.randint(k_cell, (), 0, cells.shape[0])
        off = jax.random.uniform(k_off, (2,), minval=-self.scale / 2, maxval=self.scale / 2)
        return cells[idx] + off

    def sample_goal_near(self, key: jax.Array, center: jax.Array, radius: float,
                         tries: int = 16) -> jax.Array:
        """A goal uniform over the free part of the disc of ``radius`` around ``center``
        (rejection sampling with ``tries`` candidates; ``center`` if none is free). For training
        and testing a low level on goals a few units away, as DHRL's subgoals are."""
        k_r, k_a = jax.random.split(key)
        r = radius * jnp.sqrt(jax.random.uniform(k_r, (tries,)))
        a = jax.random.uniform(k_a, (tries,), maxval=2 * jnp.pi)
        cand = center + jnp.stack([r * jnp.cos(a), r * jnp.sin(a)], -1)
        free = self.is_free(cand)
        return jnp.where(free.any(), cand[jnp.argmax(free)], center)

    def is_free(self, xy: jax.Array) -> jax.Array:
        """True where the point (x, y) lies in a free cell (any leading shape)."""
        si, sj = self._find("S")
        j = jnp.floor(xy[..., 0] / self.scale + 0.5).astype(jnp.int32) + sj
        i = jnp.floor(xy[..., 1] / self.scale + 0.5).astype(jnp.int32) + si
        rows, cols = self.grid.shape
        inside = (i >= 0) & (i < rows) & (j >= 0) & (j < cols)
        free = ~jnp.asarray(self.grid)[jnp.clip(i, 0, rows - 1), jnp.clip(j, 0, cols - 1)]
        return inside & free
