"""The helpers every method shares (``flrjax/algos/common.py``): fresh env states batched
over the runs, values unchanged."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training.types import UInt64
from jax import custom_batching

from flrjax import presets, runner
from flrjax.algos.common import batched, reset_envs
from flrjax.config import TrainConfig, make_env
from tests.tiny import DHRL


def batchedness(tree, seen: list):
    """``tree``; under a vmap, appends which of its leaves were batched to ``seen``."""

    @custom_batching.custom_vmap
    def probe(t):
        return t

    @probe.def_vmap
    def _rule(axis_size, in_batched, t):
        seen.append(in_batched[0])
        return t, in_batched[0]

    return probe(tree)


def test_batched_leaves_values_and_batches_every_leaf_under_vmap():
    seen = []

    def f(x, wrap):
        tree = {"const": jnp.arange(3.0), "mapped": x * 2.0}
        return batchedness(batched(tree) if wrap else tree, seen)

    jax.vmap(lambda x: f(x, False))(jnp.arange(4.0))
    assert seen.pop() == {"const": False, "mapped": True}  # what a scan's carry would see
    out = jax.vmap(lambda x: f(x, True))(jnp.arange(4.0))
    assert seen.pop() == {"const": True, "mapped": True}
    assert out["const"].shape == (4, 3)
    np.testing.assert_array_equal(out["const"], np.broadcast_to(np.arange(3.0), (4, 3)))
    np.testing.assert_array_equal(out["mapped"], np.arange(4.0) * 2.0)
    assert batched({"a": 1.0}) == {"a": 1.0}  # outside a vmap: itself
    count = UInt64(hi=0, lo=3)  # rebuilt from bools it would cast them to uint32 arrays
    out = jax.jit(jax.vmap(lambda x: batched({"n": count, "x": x})))(jnp.arange(4.0))
    np.testing.assert_array_equal(out["n"].lo, np.full(4, 3, np.uint32))


def test_reset_envs_is_the_vmapped_reset_and_batched_over_runs():
    env = make_env(TrainConfig(env="point3leg", out=None))
    key = jax.random.PRNGKey(3)
    want = jax.vmap(env.reset)(jax.random.split(key, 5))
    got = reset_envs(env, key, 5)
    jax.tree.map(np.testing.assert_array_equal, got, want)
    seen = []  # under a vmap over runs every field is batched, constants included
    jax.vmap(lambda k: batchedness(reset_envs(env, k, 5), seen))(jax.random.split(key, 2))
    assert all(jax.tree.leaves(seen.pop()))


@pytest.mark.parametrize("algo", ["flat", "pig", "higl"])
def test_methods_without_a_test_of_their_own_train_with_the_tuned_learner(algo):
    """The GPU default's learner switches (``--preset tuned``: normalised inputs, targets every
    5 updates) reach every method's low level: three chunks (random rounds, learning, the
    first graph) with finite parameters, and input statistics of the observations learnt from
    (DHRL's own test: tests/algos/test_dhrl.py)."""
    tuned = {k: presets.PRESETS["tuned"][k] for k in ("obs_norm", "target_update_freq")}
    cfg = dataclasses.replace(DHRL, algo=algo, **tuned)
    init, chunk, _ = runner.build(cfg)
    carry = init(jax.random.split(jax.random.key(0), 1))
    for i in range(3):
        carry, _ = chunk(carry, jnp.int32(i))
    assert bool(np.asarray(runner.params_finite(cfg.algo, carry)).all())
    low = carry.low if algo == "higl" else carry.agent  # the learner that acts in the env
    assert (np.asarray(low.obs_stats.std) != 1.0).any()
