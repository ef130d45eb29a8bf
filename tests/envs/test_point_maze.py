import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import envs


def _drive(env, state, action, n):
    step = jax.jit(env.step)
    for _ in range(n):
        state = step(state, jnp.asarray(action, jnp.float32))
    return state


def test_shapes_and_info():
    env = envs.make("point4leg")
    s = env.reset(jax.random.PRNGKey(0))
    assert s.obs.shape == (env.observation_size,) == (4,)
    assert env.action_size == 2
    for k in ("achieved_goal", "goal", "torso_z", "fallen", "success", "goal_distance", "steps"):
        assert k in s.info
    with pytest.raises(ValueError, match="action must have shape"):
        env.step(s, jnp.zeros(3))


def test_walls_block_and_sliding():
    env = envs.make("point4leg")
    s = env.reset_with_goal(jax.random.PRNGKey(0), jnp.array([0.0, 16.0]))
    # straight up from the start stops at the inner wall (face y = 4, radius 0.25), less than
    # one move (max_speed 1) short of it
    s = _drive(env, s, [0.0, 1.0], 20)
    assert 2.75 <= float(s.info["achieved_goal"][1]) <= 3.75
    # diagonal into the wall slides along it in x
    x0 = float(s.info["achieved_goal"][0])
    s = _drive(env, s, [1.0, 1.0], 5)
    assert float(s.info["achieved_goal"][0]) > x0 + 4
    assert float(s.info["achieved_goal"][1]) <= 4.0


def test_reaches_goal_in_the_room_with_a_straight_line():
    env = envs.make("point3leg")
    s = env.reset_with_goal(jax.random.PRNGKey(1), env.maze.goal)
    assert not bool(s.info["success"])
    s = _drive(env, s, [1.0, 0.0], 16)
    assert bool(s.info["success"])
    assert float(s.reward) == 0.0 and float(s.info["goal_distance"]) < 0.5
    np.testing.assert_allclose(float(s.info["goal_distance"]),
                               np.linalg.norm(np.asarray(s.info["achieved_goal"] - env.maze.goal)))
