"""The small TrainConfigs the trainer's tests share."""

import dataclasses

from flrjax import config

# the quick preset's sizes with the flat learner and chunks of 4,000 steps
QUICK = config.TrainConfig(env="point3leg", **{**config.PRESETS["quick"], "algo": "flat",
                                               "steps": 24_000, "episodes_per_chunk": 10})
# one chunk of 400 steps on small networks and batches: for the trainer's mechanics (runs,
# checkpoints, resumes, compiles), which need no learning
TINY = dataclasses.replace(QUICK, steps=400, episodes_per_chunk=1, initial_episodes=4,
                           eval_episodes=2, hidden=16, batch_size=32)
