"""The flat method (``flrjax/algos/flat.py``) apart from what every method shares."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import algos, config, runner
from tests.tiny import TINY


def test_learn_alone_makes_a_learning_rounds_updates_without_acting():
    """``learn_alone`` over an episode's env steps makes the critic steps a learning round of
    :func:`flat.train_episode` makes, on the buffer as it is, and changes the parameters."""
    cfg = dataclasses.replace(TINY, seeds=1, initial_episodes=TINY.num_envs)  # round 0 random
    init, chunk, _ = runner.build(cfg)
    carry, _ = chunk(init(jax.random.split(jax.random.key(0), 1)), jnp.int32(0))
    method = algos.get("flat")
    acfg = method.from_run(cfg, env := config.make_env(cfg))
    iters = env.config.episode_length
    alone = jax.jit(jax.vmap(lambda c, k: method.learn_alone(c, k, iters, acfg)))(
        carry, jax.random.split(jax.random.key(1), 1))
    steps = int(np.asarray(carry.agent.step)[0])
    before = [np.asarray(x) for x in jax.tree.leaves(carry.agent.actor.params)]
    learnt, _ = chunk(carry, jnp.int32(1))  # donates carry
    assert int(np.asarray(alone.step)[0]) - steps \
        == int(np.asarray(learnt.agent.step)[0]) - steps == iters * acfg.updates_per_iter > 0
    after = jax.tree.leaves(alone.actor.params)
    assert any(not np.array_equal(a, b) for a, b in zip(before, after, strict=True))
