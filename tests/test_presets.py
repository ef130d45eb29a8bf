"""The presets of a run's sizes."""

from flrjax import presets


def test_wide_is_fast_on_more_envs_per_seed():
    """The GPU default differs from the figures' protocol only in the run's shape: envs per
    seed, rounds per chunk and the initial episodes (whole rounds of envs)."""
    fast, wide = presets.PRESETS["fast"], presets.PRESETS["wide"]
    shape = {"num_envs", "episodes_per_chunk", "initial_episodes"}
    assert {k for k in fast if fast[k] != wide[k]} == shape and fast.keys() == wide.keys()
