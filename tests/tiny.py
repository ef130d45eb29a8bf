"""The small TrainConfigs the trainer's tests share."""

import dataclasses

from flrjax import config, presets

# the quick preset's sizes with the flat learner and chunks of 4,000 steps
QUICK = config.TrainConfig(env="point3leg", **{**presets.PRESETS["quick"], "algo": "flat",
                                               "steps": 24_000, "episodes_per_chunk": 10})
# one chunk of 400 steps on small networks and batches: for the trainer's mechanics (runs,
# checkpoints, resumes, compiles), which need no learning
TINY = dataclasses.replace(QUICK, steps=400, episodes_per_chunk=1, initial_episodes=4,
                           eval_episodes=2, hidden=16, batch_size=32)

# DHRL on the point mass with small networks, batches and graph (8 landmarks): the methods' pieces
DHRL = config.make(dict(env="point4leg", algo="dhrl", seeds=1, num_envs=2, steps=200,
                    episodes_per_chunk=1, batch_size=32, hidden=16, buffer_episodes=20,
                    initial_episodes=2, graph_start_steps=400, graph_every_steps=400,
                    max_landmarks=8, landmark_sample=64, eval_episodes=2))
