"""Tests for flrjax.agents.gc_td3.networks: the actor's input and the critic parametrisations."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np

from flrjax.agents.gc_td3 import networks, state
from tests.agents.gc_td3.common import CFG, OBS, G


def test_actor_input_is_obs_and_relative_goal():
    """agent.py ``_process_inputs_actor``: raw inputs (no normaliser), goal relative to obs[:g]."""
    rng = np.random.default_rng(0)
    obs = rng.normal(3.0, 2.0, size=(4, OBS)).astype(np.float32)
    goal = rng.normal(-1.0, 0.5, size=(4, G)).astype(np.float32)
    raw = networks.actor_input(CFG, obs, goal)
    np.testing.assert_allclose(raw, np.concatenate([obs, goal - obs[:, :G]], -1))


def test_critic_parametrisations_round_trip():
    """DistCritic's Q(d) and DistReverseCritic's d(Q) (agent.py) invert each other."""
    cfg, hp = state.TD3Config(), state.Hparams.create()  # gamma 0.99
    d = jnp.array([-0.5, 0.0, 1.0, 7.5, 40.0, 300.0])
    q = networks.q_from_output(d, cfg, hp)
    np.testing.assert_allclose(q, -(1 - hp.gamma ** np.asarray(d)) / (1 - hp.gamma),
                               rtol=1e-5, atol=1e-6)
    reverse = dataclasses.replace(cfg, dist_critic=False)
    np.testing.assert_array_equal(networks.q_from_output(q, reverse, hp), q)
    np.testing.assert_allclose(networks.distance_from_output(q, reverse, hp), d, rtol=1e-3,
                               atol=1e-3)
    np.testing.assert_array_equal(networks.distance_from_output(d, cfg, hp), d)
    # Q is clamped to >= 1 / (gamma - 1) + 1 before the log (agent.py get_dist), so the
    # distance saturates instead of going to inf / nan
    far = networks.distance_from_output(jnp.array([-100.0, -1e6]), reverse, hp)
    np.testing.assert_allclose(far, np.log(0.01) / np.log(0.99), rtol=1e-5)
    with_offset = dataclasses.replace(cfg, q_offset=True)
    np.testing.assert_array_equal(networks.distance_from_output(d, with_offset, hp), d + 1.0)


def test_one_minus_gamma_is_rounded_once_from_the_python_number():
    """``Hparams.create`` keeps ``1 - gamma`` as a Python float's difference rounded once, the
    float32 constant ``1.0 - gamma`` is in the arithmetic with a Python gamma; in float32,
    ``1 - float32(gamma)`` is another number, so Q(d) would move."""
    for gamma in (0.99, 0.95, 0.5):
        hp = state.Hparams.create(gamma=gamma)
        assert np.float32(hp.one_minus_gamma) == np.float32(1.0 - gamma)
        assert hp.updated(lr_actor=0.1).one_minus_gamma == hp.one_minus_gamma
        assert hp.updated(gamma=0.9).one_minus_gamma == 1.0 - 0.9
    assert np.float32(1.0 - 0.99) != np.float32(1.0) - np.float32(0.99)
    d = jnp.linspace(0.0, 50.0, 101)
    plain = jax.jit(lambda d: jnp.expm1(d * jnp.log(0.99)) / (1.0 - 0.99))(d)
    traced = jax.jit(networks.q_from_output, static_argnums=1)(
        d, state.TD3Config(), jax.tree.map(jnp.float32, state.Hparams.create()))
    np.testing.assert_array_equal(traced, plain)


def test_normalised_inputs_use_the_observations_statistics_for_the_goal_too():
    """--obs-norm: the observation as (obs - mean) / std; a relative goal scaled by the
    achieved goal's std (a difference, no shift), an absolute one shifted and scaled as the
    achieved goal, the first G entries of the observation."""
    rng = np.random.default_rng(1)
    obs = rng.normal(3.0, 2.0, size=(4, OBS)).astype(np.float32)
    goal = rng.normal(-1.0, 0.5, size=(4, G)).astype(np.float32)
    action = rng.uniform(-1, 1, size=(4, 2)).astype(np.float32)
    mean = rng.normal(size=OBS).astype(np.float32)
    std = rng.uniform(0.5, 4.0, size=OBS).astype(np.float32)
    stats = SimpleNamespace(mean=mean, std=std)
    z = (obs - mean) / std
    np.testing.assert_allclose(networks.actor_input(CFG, obs, goal, stats=stats),
                               np.concatenate([z, (goal - obs[:, :G]) / std[:G]], -1),
                               rtol=1e-6)
    absolute = dataclasses.replace(CFG, absolute_goal=True)
    g_z = (goal - mean[:G]) / std[:G]
    np.testing.assert_allclose(networks.actor_input(absolute, obs, goal, stats=stats),
                               np.concatenate([z, g_z], -1), rtol=1e-6)
    np.testing.assert_allclose(networks.critic_input(CFG, obs, goal, action, stats=stats),
                               np.concatenate([z, g_z, action], -1), rtol=1e-6)
