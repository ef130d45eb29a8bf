"""The presets of a run's sizes."""

from flrjax import presets


def test_wide_is_fast_on_more_envs_per_seed():
    """The GPU default differs from the figures' protocol only in the run's shape: envs per
    seed, rounds per chunk and the initial episodes (whole rounds of envs)."""
    fast, wide = presets.PRESETS["fast"], presets.PRESETS["wide"]
    shape = {"num_envs", "episodes_per_chunk", "initial_episodes"}
    assert {k for k in fast if fast[k] != wide[k]} == shape and fast.keys() == wide.keys()


def test_tuned_is_wide_with_normalised_inputs_and_targets_every_5_updates():
    """The GPU default differs from ``wide`` only in the low level's learner: its inputs
    normalised and its target networks stepped twice as often."""
    wide, tuned = presets.PRESETS["wide"], presets.PRESETS["tuned"]
    assert {k: v for k, v in tuned.items() if wide.get(k) != v} == {
        "target_update_freq": 5, "obs_norm": True}
    assert wide.keys() <= tuned.keys()
