"""Tests for flrjax.agents.gc_td3.networks: the actor's input and the critic parametrisations."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from flrjax.agents.gc_td3 import networks
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
    cfg = networks.TD3Config()  # gamma 0.99
    d = jnp.array([-0.5, 0.0, 1.0, 7.5, 40.0, 300.0])
    q = networks.q_from_output(d, cfg)
    np.testing.assert_allclose(q, -(1 - cfg.gamma ** np.asarray(d)) / (1 - cfg.gamma),
                               rtol=1e-5, atol=1e-6)
    reverse = dataclasses.replace(cfg, dist_critic=False)
    np.testing.assert_array_equal(networks.q_from_output(q, reverse), q)
    np.testing.assert_allclose(networks.distance_from_output(q, reverse), d, rtol=1e-3,
                               atol=1e-3)
    np.testing.assert_array_equal(networks.distance_from_output(d, cfg), d)
    # Q is clamped to >= 1 / (gamma - 1) + 1 before the log (agent.py get_dist), so the
    # distance saturates instead of going to inf / nan
    far = networks.distance_from_output(jnp.array([-100.0, -1e6]), reverse)
    np.testing.assert_allclose(far, np.log(0.01) / np.log(0.99), rtol=1e-5)
    with_offset = dataclasses.replace(cfg, q_offset=True)
    np.testing.assert_array_equal(networks.distance_from_output(d, with_offset), d + 1.0)
