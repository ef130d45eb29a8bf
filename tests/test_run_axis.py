"""Tests for flrjax.run_axis: the runs padded to a multiple of the devices (here only counted:
the programs split over forced CPU devices are in tests/test_runner.py)."""

import jax
import numpy as np

from flrjax import run_axis
from tests.tiny import TINY

#: 3 seeds x 2 sweep points, said to be split over 4 devices: padded to 8 runs.
CFG = TINY.replace(seeds=3, lr_critic=(1e-3, 3e-4), devices=4)


def test_padding_runs_copy_the_last_runs_values_and_are_dropped_again():
    values = {"lr": np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])}
    padded = run_axis.pad_runs(CFG, values)
    np.testing.assert_array_equal(padded["lr"], [1, 1, 1, 2, 2, 2, 2, 2])
    np.testing.assert_array_equal(run_axis.real_runs(CFG, padded)["lr"], values["lr"])


def test_keys_per_seed_for_every_point_and_own_keys_for_the_padding():
    """Seed s meets the same key at every sweep point; the real runs' keys are those of the
    unpadded program; the padding runs' keys are new."""
    keys = np.asarray(run_axis.run_keys(CFG, jax.random.PRNGKey(0)))
    plain = np.asarray(run_axis.run_keys(CFG.replace(devices=1), jax.random.PRNGKey(0)))
    assert keys.shape == (8, 2) and plain.shape == (6, 2)
    np.testing.assert_array_equal(keys[:6], plain)
    np.testing.assert_array_equal(plain[:3], plain[3:])
    assert len({tuple(k) for k in keys}) == 3 + 2

