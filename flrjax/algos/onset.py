"""The onset of success: a freshly built landmark graph, the states it was picked from and the
high level's subgoals judged against the maze's true path lengths (:mod:`flrjax.envs.geodesic`),
as ``stats/`` metrics of the hierarchical methods. Success stays at zero for a long stretch of
training; these say whether exploration, the planner's distances, its edges, its reach or the
subgoals are not yet right."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import State

from flrjax import planner, replay
from flrjax.envs import geodesic
from flrjax.envs.maze import Maze

#: An edge crosses a wall where the true path between its ends is longer than ``WALL_RATIO``
#: times the straight line, beyond the geodesic table's own error (``WALL_SLACK`` squares).
WALL_RATIO = 1.5
WALL_SLACK = 3
#: The names of :func:`graph_stats`.
GRAPH_STATS = ("dist_rank_corr", "wall_edge_frac", "goal_landmark_gap", "path_to_goal")
#: The names of :func:`reach_stats`.
REACH_STATS = ("sample_goal_gap", "replay_goal_gap")
#: The names of :func:`build_stats`.
BUILD_STATS = (*GRAPH_STATS, *REACH_STATS)


def _ranks(x: jax.Array, mask: jax.Array) -> jax.Array:
    """Ranks of ``x`` among its ``mask``-ed entries (average ranks for ties); the others rank
    last and are never read."""
    v = jnp.where(mask, x, jnp.inf).ravel()
    s = jnp.sort(v)
    lo, hi = jnp.searchsorted(s, v, side="left"), jnp.searchsorted(s, v, side="right")
    return ((lo + hi - 1) / 2).reshape(x.shape)


def rank_corr(x: jax.Array, y: jax.Array, mask: jax.Array) -> jax.Array:
    """Spearman's rank correlation of ``x`` and ``y`` over the ``mask``-ed entries where both
    are finite (Pearson's on average ranks); NaN where one of them is constant or empty."""
    mask = mask & jnp.isfinite(x) & jnp.isfinite(y)
    rx, ry = _ranks(x, mask), _ranks(y, mask)
    n = jnp.maximum(mask.sum(), 1)
    dx = jnp.where(mask, rx - jnp.where(mask, rx, 0.0).sum() / n, 0.0)
    dy = jnp.where(mask, ry - jnp.where(mask, ry, 0.0).sum() / n, 0.0)
    return (dx * dy).sum() / jnp.sqrt((dx * dx).sum() * (dy * dy).sum())


def graph_stats(graph: planner.Graph, pdist: jax.Array, maze: Maze) -> dict:
    """How well a freshly built graph knows ``maze``, against its true path lengths
    (:mod:`flrjax.envs.geodesic`): the success stays at zero until the planner's distances,
    edges and reach are right, and these say which of them is not yet.

    - ``dist_rank_corr``: rank correlation, over all pairs of landmarks, of the distance
      critics' estimates ``pdist`` (the edge weights before the cutoff) with the true path
      lengths: does the critic order distances as the maze does;
    - ``wall_edge_frac``: the fraction of the graph's edges that cross a wall (true path
      longer than :data:`WALL_RATIO` x the straight line): shortcuts the low level cannot
      follow;
    - ``goal_landmark_gap``: the true path from the maze's goal to its nearest landmark: has
      exploration reached the goal's region yet;
    - ``path_to_goal``: 1 if the graph connects the landmarks nearest the maze's start and
      goal, else 0 (its mean over a chunk's rebuilds is a fraction).

    NaN where the graph has no landmark or no edge."""
    geo = geodesic.table(maze)
    lm = graph.landmarks
    k = lm.mask.shape[0]
    pair = lm.mask[:, None] & lm.mask[None, :] & ~jnp.eye(k, dtype=bool)
    true = geodesic.distance(geo, lm.goal[:, None], lm.goal[None, :])
    straight = jnp.linalg.norm(lm.goal[:, None] - lm.goal[None, :], axis=-1)
    edge = pair & jnp.isfinite(graph.weight)
    wall = true > WALL_RATIO * straight + WALL_SLACK * geo.size
    n_edge = edge.sum()
    from_start = jnp.where(lm.mask, geodesic.distance(geo, maze.start, lm.goal), jnp.inf)
    to_goal = jnp.where(lm.mask, geodesic.distance(geo, lm.goal, maze.goal), jnp.inf)
    linked = jnp.isfinite(graph.dist[jnp.argmin(from_start), jnp.argmin(to_goal)])
    nan = jnp.where(lm.mask.any(), 1.0, jnp.nan)
    stats = (rank_corr(pdist, true, pair),
             (edge & wall).sum() / jnp.where(n_edge > 0, n_edge, jnp.nan),
             to_goal.min() * nan, linked * nan)
    return {k: v.astype(jnp.float32) for k, v in zip(GRAPH_STATS, stats, strict=True)}


def reach_stats(maze: Maze, sampled_goal: jax.Array, buffer: replay.ReplayState) -> dict:
    """How near the maze's goal the states a graph is built from have come, beside its
    ``goal_landmark_gap``: the landmarks are picked from a sample of the replay, so the gap
    of the landmarks is at least that of the sample, and that at least the replay's. Which
    of them lags says whether exploration or the choice of landmarks holds the onset back.

    - ``sample_goal_gap``: the true path from the goal to the nearest of ``sampled_goal[N, 2]``
      (the achieved goals the landmarks were picked from);
    - ``replay_goal_gap``: the same over every state of the complete episodes in ``buffer``
      (its ``achieved_goal``, what sampling can draw: :func:`flrjax.replay.stored_mask`).

    NaN where the replay holds no complete episode."""
    geo = geodesic.table(maze)
    stored = replay.stored_mask(buffer)
    to_goal = geodesic.distance(geo, buffer.states["achieved_goal"], maze.goal)
    nan = jnp.where(stored.any(), 1.0, jnp.nan)
    stats = (geodesic.distance(geo, sampled_goal, maze.goal).min() * nan,
             jnp.where(stored[:, None], to_goal, jnp.inf).min() * nan)
    return {k: v.astype(jnp.float32) for k, v in zip(REACH_STATS, stats, strict=True)}


def build_stats(graph: planner.Graph, pdist: jax.Array, maze: Maze, sampled_goal: jax.Array,
                buffer: replay.ReplayState) -> dict:
    """A graph build's :func:`graph_stats` and :func:`reach_stats`: the graph, and how near
    the goal the states it was picked from (``sampled_goal`` of ``buffer``) have come."""
    return {**graph_stats(graph, pdist, maze), **reach_stats(maze, sampled_goal, buffer)}


def subgoal_stats(maze: Maze, start: State, end: State, subgoal: jax.Array) -> dict:
    """A subgoal period's high-level choice against ``maze``'s true path lengths, averaged
    over the envs (``start``/``end``: the period's first and last states, ``subgoal[E, 2]``):
    does the high level ask for the right thing, and does the low level deliver it.

    - ``subgoal_progress``: true path to the final goal from where the agent chose minus from
      the subgoal (positive: the subgoal lies closer to the goal along the maze);
    - ``period_progress``: the same from where the agent chose minus from where it ended the
      period (what the low level achieved of it);
    - ``subgoal_distance``: true path from where the agent chose to the subgoal (how far the
      low level is asked to walk in one period)."""
    geo = geodesic.table(maze)
    here, there = start.info["achieved_goal"], end.info["achieved_goal"]
    goal = start.info["goal"]
    to_goal = geodesic.distance(geo, here, goal)
    return {"subgoal_progress": (to_goal - geodesic.distance(geo, subgoal, goal)).mean(),
            "period_progress": (to_goal - geodesic.distance(geo, there, goal)).mean(),
            "subgoal_distance": geodesic.distance(geo, here, subgoal).mean()}
