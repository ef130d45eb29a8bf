"""The presets of a run's sizes (``--preset``): each sets the flags it names; any flag given
overrides its preset's value."""

from __future__ import annotations

import jax

#: The reference's networks on 16 lockstep envs per seed with an update every 4 env steps and
#: DHRL's 200 random episodes rounded to the envs (192): the protocol of the GPU figures
#: (docs/results.md).
FAST = dict(steps=1_920_000, num_envs=16, updates_per_step=0.25, episodes_per_chunk=5,
            batch_size=1024, hidden=256, buffer_episodes=2500, initial_episodes=192,
            polyak=0.995, target_update_freq=10)

#: ``fast`` on 128 envs per seed, one episode round (and one evaluation) per chunk: the same
#: updates per env step; FLR+DHRL learns as much per env step, in fewer seconds.
WIDE = {**FAST, "num_envs": 128, "episodes_per_chunk": 1, "initial_episodes": 256}

PRESETS: dict[str, dict] = {
    # A short CPU run on a point mass that shows learning within a few thousand steps, with an
    # evaluation every 800 steps. Small networks and batches; targets follow every update
    # (0.99), as suits a run this short (the reference's 0.995 every 10 updates suits a
    # million steps).
    "quick": dict(steps=9_600, num_envs=4, updates_per_step=1.0, episodes_per_chunk=2,
                  batch_size=256, hidden=64, buffer_episodes=400, initial_episodes=8,
                  polyak=0.99, target_update_freq=1),
    # The reference's scale: one update per env step on one env.
    "paper": {**FAST, "steps": 1_200_000, "num_envs": 1, "updates_per_step": 1.0,
              "initial_episodes": 10},
    "fast": FAST,
    "wide": WIDE,
    # ``wide`` with a tuned low-level learner, not the reference's: its network inputs
    # normalised by running statistics, the target networks stepped every 5 updates
    # (docs/results.md, "What the onset of success waits for").
    "tuned": {**WIDE, "target_update_freq": 5, "obs_norm": True},
}


def default_preset() -> str:
    """``--preset auto``: ``tuned`` on a GPU (the tripod's result in the fewest seconds),
    ``quick`` on a CPU."""
    return "quick" if jax.default_backend() == "cpu" else "tuned"
