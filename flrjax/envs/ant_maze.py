"""AntMaze on MuJoCo MJX with brax's ``Env``/``State`` API.

The env is a thin layer over ``mjx.step``: ``step`` writes the action into ``ctrl``, runs
``frame_skip`` physics substeps in a ``lax.scan`` and reads a handful of entries of ``qpos`` and
``qvel``. Nothing else runs per step (no contact-force readout, no ``mjx.forward``, no
per-link transforms), which is why it costs what the physics costs (see
``benchmarks/env_throughput.py``); ``reset`` does not run ``mjx.forward`` either.

Reference numbers (jayLEE0301/dhrl_official): observation ``qpos[:15] ++ qvel[:14]`` for the
4-legged ant (``envs/antenv/ant_maze_bottleneck.py``, ``_get_obs``; here ``qpos ++ qvel`` of an
n-legged ant, 29 numbers for 4 legs, 25 for 3), frame skip 5 (``MujocoEnv.__init__(..., 5)``
there), reset noise U(-0.1, 0.1) on the joint angles and N(0, 0.1) on the velocities with the
torso's x, y kept at the start (``reset_model``), episodes of 600 steps (``EnvWithGoal.step``),
success within 5 of the goal (``info['is_success']``), evaluation goal (0, 16) (``reset``).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
from brax.envs.base import Env, State
from mujoco import mjx

from flrjax.envs.ant_xml import AntSpec, ant_maze_xml
from flrjax.envs.maze import Maze


@dataclasses.dataclass(frozen=True)
class AntMazeConfig:
    """Task parameters of an ant maze (physics parameters live in :class:`AntSpec`)."""

    episode_length: int = 600  # dhrl_official scripts/AntMaze.sh --max_steps 600
    frame_skip: int = 5
    reset_noise: float = 0.1
    delta: float = 0.5  # goal threshold of eq. (1): distance_threshold 0.5 in the reference
    success_radius: float = 5.0  # evaluation success: paper §3.1 and EnvWithGoal.step
    # Torso height under which the ant counts as fallen: between the lowest upright (tilt < 60
    # deg) torso under random torques and an ant resting on its back (docs/results.md).
    fall_z: float = 0.3
    # None: training goals uniform over the free area (the reference). A number: uniform over
    # the free part of the disc of that radius around the start (goals a few units away).
    goal_radius: float | None = None


class AntMaze(Env):
    """An n-legged ant that must reach a goal (x, y) in a maze.

    ``state.info`` holds ``achieved_goal`` (torso x, y), ``goal``, ``torso_z``, ``fallen``,
    ``success``, ``goal_distance`` and ``steps``. ``reward`` is the sparse reward of eq. (1) for
    the final goal; ``done`` is 1 once ``episode_length`` steps have run (there is no other
    termination, as in the reference).
    """

    def __init__(self, spec: AntSpec, maze: Maze, config: AntMazeConfig = AntMazeConfig()):
        self.spec, self.maze, self.config = spec, maze, config
        self.xml = ant_maze_xml(spec, maze)
        self.mj_model = mujoco.MjModel.from_xml_string(self.xml)
        self.sys = mjx.put_model(self.mj_model)
        self._qpos0 = jnp.asarray(self.mj_model.qpos0)
        self._nq, self._nv = self.mj_model.nq, self.mj_model.nv

    # brax Env API -------------------------------------------------------------------------
    @property
    def observation_size(self) -> int:
        return self._nq + self._nv

    @property
    def action_size(self) -> int:
        return self.mj_model.nu

    @property
    def backend(self) -> str:
        return "mjx"

    @property
    def goal_size(self) -> int:
        return 2

    def reset(self, rng: jax.Array) -> State:
        """A new episode with a goal drawn uniformly over the maze's free area (or near the
        start, with ``config.goal_radius``)."""
        k_goal, k_state = jax.random.split(rng)
        if self.config.goal_radius is None:
            goal = self.maze.sample_goal(k_goal)
        else:
            goal = self.maze.sample_goal_near(k_goal, jnp.asarray(self.maze.start),
                                              self.config.goal_radius)
        return self.reset_with_goal(k_state, goal)

    def reset_with_goal(self, rng: jax.Array, goal: jax.Array) -> State:
        """A new episode towards ``goal`` (e.g. the evaluation goal ``maze.goal``)."""
        qpos, qvel = self.noisy_start(rng)
        # No mjx.forward: the next mjx.step recomputes every derived field from qpos and qvel
        # (its solver starts from qacc_warmstart = 0 either way), so trajectories are
        # bit-identical without it (tests/envs/test_ant_maze.py) and the programs that reset
        # hold one copy of the physics' forward pass, not two. Its one lasting effect, the
        # torso's quaternion normalised, is done here with mjx's formula (q / norm(q) alone
        # may compile to q * rsqrt(.) and differ in the last bit).
        quat = qpos[3:7]
        norm = jnp.linalg.norm(quat)
        qpos = qpos.at[3:7].set(quat / (norm + 1e-6 * (norm == 0.0)))
        data = mjx.make_data(self.sys).replace(qpos=qpos, qvel=qvel)
        zero = jnp.zeros((), jnp.int32)
        return self._state(data, jnp.asarray(goal, jnp.float32), zero, zero)

    def noisy_start(self, rng: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The reference's start (``reset_model``), before normalisation: every coordinate
        + U(-reset_noise, reset_noise) but the torso's x, y, velocities N(0, reset_noise)."""
        k_pos, k_vel = jax.random.split(rng)
        noise = self.config.reset_noise
        qpos = self._qpos0 + jax.random.uniform(k_pos, (self._nq,), minval=-noise, maxval=noise)
        qpos = qpos.at[:2].set(self._qpos0[:2])
        qvel = noise * jax.random.normal(k_vel, (self._nv,))
        return qpos, qvel

    def step(self, state: State, action: jax.Array) -> State:
        """``frame_skip`` physics substeps with ``ctrl = clip(action, -1, 1)``."""
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},), got {action.shape}")
        data = state.pipeline_state.replace(ctrl=jnp.clip(action, -1.0, 1.0))

        def substep(d, _):
            return mjx.step(self.sys, d), None

        data, _ = jax.lax.scan(substep, data, None, length=self.config.frame_skip)
        # An unstable step (non-finite qpos or qvel, e.g. from a NaN action) would poison the
        # whole batch through the replay and the critics: put that env back at the start pose,
        # at rest, and count it. The last finite data, with its pose and velocities replaced,
        # stands in for a fresh one (mjx.step recomputes everything else from qpos and qvel,
        # and a fresh mjx.forward here would cost as much as a substep on every step).
        unstable = ~(jnp.isfinite(data.qpos).all() & jnp.isfinite(data.qvel).all())
        rest = state.pipeline_state.replace(qpos=self._qpos0, qvel=jnp.zeros(self._nv),
                                            ctrl=jnp.zeros(self.action_size))
        data = jax.tree.map(lambda r, d: jnp.where(unstable, r, d), rest, data)
        return self._state(data, state.info["goal"], state.info["steps"] + 1,
                           state.info["physics_resets"] + unstable)

    # helpers --------------------------------------------------------------------------------
    def _state(self, data: mjx.Data, goal: jax.Array, steps: jax.Array,
               physics_resets: jax.Array) -> State:
        xy = data.qpos[:2]
        dist = jnp.linalg.norm(xy - goal)
        info = {
            "achieved_goal": xy,
            "goal": goal,
            "torso_z": data.qpos[2],
            "fallen": data.qpos[2] < self.config.fall_z,
            "success": dist <= self.config.success_radius,
            "goal_distance": dist,
            "steps": steps,
            "physics_resets": physics_resets.astype(jnp.int32),
        }
        return State(
            pipeline_state=data,
            obs=jnp.concatenate([data.qpos, data.qvel]),
            # float32, not weakly typed as from the bare 0.0 and -1.0: a checkpoint restores
            # the carry strongly typed, and the chunk would recompile for it.
            reward=jnp.where(dist < self.config.delta, 0.0, -1.0).astype(jnp.float32),
            done=(steps >= self.config.episode_length).astype(jnp.float32),
            info=info,
        )
