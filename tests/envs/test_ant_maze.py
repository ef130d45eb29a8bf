"""MJX ant mazes on the CPU: few envs, one compiled reset and one compiled 50-step rollout each."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco import mjx

from flrjax import envs

B, T = 8, 50


@functools.cache
def compiled(name: str):
    env = envs.make(name)

    def rollout(state, actions):
        def f(s, a):
            s = env.step(s, a)
            return s, (s.info["achieved_goal"], s.info["torso_z"], s.info["fallen"])

        return jax.lax.scan(f, state, actions)

    return env, jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(rollout))


def _keys(seed: int = 0):
    return jax.random.split(jax.random.PRNGKey(seed), B)


def _set(state, qpos=None, qvel=None):
    d = state.pipeline_state
    return state.replace(pipeline_state=d.replace(
        qpos=d.qpos if qpos is None else qpos, qvel=d.qvel if qvel is None else qvel))


@pytest.mark.parametrize("name,n_legs", [("ant4leg", 4), ("ant3leg", 3)])
def test_shapes_dtypes_and_determinism(name, n_legs):
    env, reset, _ = compiled(name)
    assert env.action_size == 2 * n_legs
    assert env.observation_size == (7 + 2 * n_legs) + (6 + 2 * n_legs)  # qpos ++ qvel
    s = reset(_keys())
    assert s.obs.shape == (B, env.observation_size) and s.obs.dtype == jnp.float32
    assert s.info["achieved_goal"].shape == (B, 2) and s.info["goal"].shape == (B, 2)
    assert s.info["fallen"].dtype == jnp.bool_ and s.info["success"].dtype == jnp.bool_
    np.testing.assert_allclose(s.info["achieved_goal"], 0.0)  # start cell centre is the origin
    s2 = reset(_keys())
    np.testing.assert_array_equal(s.obs, s2.obs)
    np.testing.assert_array_equal(s.info["goal"], s2.info["goal"])
    s3 = reset(_keys(1))
    assert not np.allclose(s.obs, s3.obs)
    assert np.asarray(env.maze.is_free(s.info["goal"])).all()


def test_reset_without_forward_gives_the_same_trajectories():
    """``reset`` normalises the torso's quaternion instead of running ``mjx.forward`` (the next
    ``mjx.step`` recomputes every derived field): random-action rollouts from it match, bit
    for bit, those from the former reset, the noisy start put through ``mjx.forward``."""
    env, reset, rollout = compiled("ant3leg")
    s = reset(_keys())

    def former_reset(key):
        qpos, qvel = env.noisy_start(jax.random.split(key)[1])  # as reset splits its key
        return mjx.forward(env.sys, mjx.make_data(env.sys).replace(qpos=qpos, qvel=qvel))

    forwarded = s.replace(pipeline_state=jax.jit(jax.vmap(former_reset))(_keys()))
    np.testing.assert_array_equal(s.pipeline_state.qpos, forwarded.pipeline_state.qpos)
    assert not np.array_equal(s.pipeline_state.xpos, forwarded.pipeline_state.xpos)
    acts = jax.random.uniform(jax.random.PRNGKey(5), (B, T, env.action_size), minval=-1)
    (end, out), (end_f, out_f) = rollout(s, acts), rollout(forwarded, acts)
    for a, b in zip((end.obs, end.pipeline_state.qacc_warmstart, *out),
                    (end_f.obs, end_f.pipeline_state.qacc_warmstart, *out_f), strict=True):
        np.testing.assert_array_equal(a, b)


def test_ant4leg_stands_still_and_survives_random_actions():
    env, reset, rollout = compiled("ant4leg")
    s = reset(_keys())
    s, (xy, z, fallen) = rollout(s, jnp.zeros((B, T, env.action_size)))
    assert np.isfinite(np.asarray(s.obs)).all()
    assert np.abs(np.asarray(xy)).max() < 0.3  # does not drift
    assert 0.35 < np.asarray(z[:, -1]).min() and np.asarray(z[:, -1]).max() < 0.8
    assert np.abs(np.asarray(s.pipeline_state.qvel)).max() < 0.5  # at rest
    assert not np.asarray(fallen).any()
    # 30 s of uniformly random torques: the converged MuJoCo solver never flips the 4-legged ant
    # (0/30 episodes); a too-weak solver (1 Newton iteration) flips nearly all of them.
    acts = jax.random.uniform(jax.random.PRNGKey(3), (6, B, T, env.action_size), minval=-1)
    for a in acts:
        s, (_, _, fallen) = rollout(s, a)
    assert np.isfinite(np.asarray(s.obs)).all()
    assert np.asarray(fallen[:, -1]).sum() <= 1


def test_walls_block_the_ant():
    env, reset, rollout = compiled("ant4leg")
    s = reset(_keys())
    qpos, qvel = s.pipeline_state.qpos, s.pipeline_state.qvel
    # lanes 0-3: from (0, 2) thrown at 8 m/s towards +y, into the inner wall whose face is y = 4;
    # lanes 4-7: from (-1, 0) thrown towards -x, into the outer wall whose face is x = -4.
    qpos = qpos.at[:4, :2].set(jnp.array([0.0, 2.0])).at[4:, :2].set(jnp.array([-1.0, 0.0]))
    qvel = qvel.at[:4, 1].set(8.0).at[4:, 0].set(-8.0)
    s, (xy, _, _) = rollout(_set(s, qpos, qvel), jnp.zeros((B, T, env.action_size)))
    xy = np.asarray(xy)
    assert np.isfinite(xy).all()
    assert xy[:4, :, 1].max() > 3.0  # it did reach the wall...
    assert xy[:4, :, 1].max() < 4.0 - 0.2  # ...and the torso (radius 0.25) stayed out of it
    assert xy[4:, :, 0].min() < -2.5
    assert xy[4:, :, 0].min() > -4.0 + 0.2


def test_tripod_falls_when_tipped_and_not_otherwise():
    env, reset, rollout = compiled("ant3leg")
    s = reset(_keys())
    qpos = s.pipeline_state.qpos
    # lanes 4-7: rolled 150° about x (nearly upside down), 0.6 above the floor
    tipped = jnp.array([0.0, 0.0, 0.6, np.cos(np.radians(75)), np.sin(np.radians(75)), 0.0, 0.0])
    qpos = qpos.at[4:, :7].set(tipped)
    s, (_, z, fallen) = rollout(_set(s, qpos), jnp.zeros((B, T, env.action_size)))
    fallen, z = np.asarray(fallen), np.asarray(z)
    assert not fallen[:4].any()
    assert fallen[4:, -1].all()
    assert (z[4:, -1] < env.config.fall_z).all() and (z[:4, -1] > 0.35).all()
    np.testing.assert_array_equal(np.asarray(s.info["fallen"]), fallen[:, -1])


def test_success_and_goal_distance_as_documented():
    env, reset, rollout = compiled("ant3leg")
    s = reset(_keys())
    # goals at distances 0.3, 4.9, 5.1 and 12 from the (resting) torso
    d = jnp.array([0.3, 4.9, 5.1, 12.0, 0.3, 4.9, 5.1, 12.0])
    s = s.replace(info={**s.info, "goal": jnp.stack([d, jnp.zeros(B)], -1)})
    s, _ = rollout(s, jnp.zeros((B, T, env.action_size)))
    dist = np.linalg.norm(np.asarray(s.info["achieved_goal"] - s.info["goal"]), axis=-1)
    np.testing.assert_allclose(s.info["goal_distance"], dist, rtol=1e-5)
    np.testing.assert_array_equal(s.info["success"], dist <= env.config.success_radius)
    np.testing.assert_array_equal(s.reward, np.where(dist < env.config.delta, 0.0, -1.0))
    assert list(np.asarray(s.info["success"][:4])) == [True, True, False, False]
    assert (np.asarray(s.info["steps"]) == T).all() and not np.asarray(s.done).any()


def test_bad_input_is_reported_clearly():
    with pytest.raises(ValueError, match="unknown env 'nope'; valid: ant3leg, ant4leg"):
        envs.make("nope")
    with pytest.raises(ValueError, match="unknown env option"):
        envs.make("ant4leg", legs=5)
    env, reset, _ = compiled("ant4leg")
    s = jax.tree.map(lambda x: x[0], reset(_keys()))
    with pytest.raises(ValueError, match=r"action must have shape \(8,\)"):
        env.step(s, jnp.zeros(3))


def test_unstable_physics_resets_that_env_and_is_counted():
    """A NaN action makes the physics non-finite in envs 0 and 3 only: those go back to the
    start pose at rest and count a reset; the others are untouched."""
    env, reset, rollout = compiled("ant3leg")
    s = reset(_keys())
    actions = jnp.zeros((B, T, env.action_size)).at[jnp.array([0, 3]), 10].set(jnp.nan)
    s_bad, (xy, z, _) = rollout(s, actions)
    s_ok, (xy_ok, _, _) = rollout(s, jnp.zeros((B, T, env.action_size)))
    assert np.isfinite(np.asarray(s_bad.obs)).all() and np.isfinite(np.asarray(xy)).all()
    np.testing.assert_array_equal(s_bad.info["physics_resets"], [1, 0, 0, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(s_bad.obs[1], s_ok.obs[1])
    np.testing.assert_allclose(xy[0, 10], 0.0)  # back at the start cell's centre
    assert float(z[0, -1]) > env.config.fall_z  # and upright
