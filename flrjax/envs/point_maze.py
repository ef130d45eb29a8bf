"""A point mass in the same maze layouts, in pure JAX: fast on a CPU, for learning tests.

The point moves by ``max_speed · clip(action, -1, 1)`` per step and slides along walls: a move
that would put its disc (radius ``radius``) into a wall cell is tried along x alone, then y
alone, and dropped if both collide (so it stops less than one move short of a wall).
``max_speed`` is far below the wall thickness, so it can never tunnel. Its ``state.info``
carries the same keys as :class:`AntMaze` (``torso_z`` is a constant and ``fallen`` always
False) so the trainer and metrics need no special case.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State

from flrjax.envs.maze import Maze


@dataclasses.dataclass(frozen=True)
class PointMazeConfig:
    episode_length: int = 100
    max_speed: float = 1.0
    radius: float = 0.25
    delta: float = 0.5
    success_radius: float = 5.0
    reset_noise: float = 0.1


class PointMaze(Env):
    """Point mass with observation (x, y, vx, vy) and action (dx, dy) in [-1, 1]^2."""

    def __init__(self, maze: Maze, config: PointMazeConfig = PointMazeConfig()):
        self.maze, self.config = maze, config
        self._start = jnp.asarray(maze.start)

    @property
    def observation_size(self) -> int:
        return 4

    @property
    def action_size(self) -> int:
        return 2

    @property
    def backend(self) -> str:
        return "jax"

    @property
    def goal_size(self) -> int:
        return 2

    def reset(self, rng: jax.Array) -> State:
        k_goal, k_state = jax.random.split(rng)
        return self.reset_with_goal(k_state, self.maze.sample_goal(k_goal))

    def reset_with_goal(self, rng: jax.Array, goal: jax.Array) -> State:
        noise = self.config.reset_noise
        xy = self._start + jax.random.uniform(rng, (2,), minval=-noise, maxval=noise)
        return self._state(xy, jnp.zeros(2), jnp.asarray(goal, jnp.float32), jnp.int32(0))

    def step(self, state: State, action: jax.Array) -> State:
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},), got {action.shape}")
        xy = state.info["achieved_goal"]
        move = self.config.max_speed * jnp.clip(action, -1.0, 1.0)
        candidates = jnp.stack([xy + move, xy + move * jnp.array([1.0, 0.0]),
                                xy + move * jnp.array([0.0, 1.0]), xy])
        ok = jax.vmap(self._disc_free)(candidates).at[-1].set(True)
        new_xy = candidates[jnp.argmax(ok)]
        return self._state(new_xy, new_xy - xy, state.info["goal"], state.info["steps"] + 1)

    def _disc_free(self, xy: jax.Array) -> jax.Array:
        r = self.config.radius
        corners = xy + r * jnp.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]])
        return jnp.all(self.maze.is_free(corners))

    def _state(self, xy: jax.Array, vel: jax.Array, goal: jax.Array, steps: jax.Array) -> State:
        dist = jnp.linalg.norm(xy - goal)
        info = {
            "achieved_goal": xy,
            "goal": goal,
            "torso_z": jnp.float32(self.config.radius),
            "fallen": jnp.bool_(False),
            "success": dist <= self.config.success_radius,
            "goal_distance": dist,
            "steps": steps,
            "physics_resets": jnp.int32(0),  # the point mass has no unstable physics
        }
        return State(
            pipeline_state=None,
            obs=jnp.concatenate([xy, vel]),
            # float32, not weakly typed as from the bare 0.0 and -1.0: a checkpoint restores
            # the carry strongly typed, and the chunk would recompile for it.
            reward=jnp.where(dist < self.config.delta, 0.0, -1.0).astype(jnp.float32),
            done=(steps >= self.config.episode_length).astype(jnp.float32),
            info=info,
        )
