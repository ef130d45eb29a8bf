"""PIG on the point mass: planned waypoints stored for the imitation, and one jitted run."""

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import train

TINY = train.TrainConfig(env="point4leg", algo="flr_pig", seeds=1, num_envs=2, steps=200,
                         episodes_per_chunk=1, batch_size=32, hidden=16, buffer_episodes=20,
                         initial_episodes=2, graph_start_steps=200, graph_every_steps=200,
                         max_landmarks=8, landmark_sample=64, eval_episodes=2,
                         flr_candidates=4)


def test_plans_are_stored_for_the_imitation_once_the_graph_exists():
    init, chunk, evaluate = train.build(TINY)
    acfg = train.algo_config(TINY)
    assert acfg.base.low.imitation_weight == train.PIG_IMITATION_WEIGHT
    assert acfg.base.flr is not None and acfg.path_len == 10
    carry = init(jax.random.split(jax.random.key(0), 1))
    metrics = []
    for i in range(3):
        carry, m = chunk(carry, jnp.int32(i))
        metrics.append(jax.tree.map(lambda x: float(np.asarray(x).mean()), m))
    assert metrics[0]["graph_nodes"] == 0 and metrics[0]["planned_steps"] == 0
    assert metrics[0]["critic_loss"] == 0  # the random round does not learn
    assert metrics[2]["graph_nodes"] >= 1 and np.isfinite(metrics[2]["imitation"])
    tr = jax.tree.map(lambda x: np.asarray(x)[0], carry.buffer.transitions)
    graph = jax.tree.map(lambda x: np.asarray(x)[0], carry.graph)
    landmarks = graph.landmarks.goal[graph.landmarks.mask]
    mask, goals = tr["imitation_mask"][:6], tr["imitation_goal"][:6]  # [episode, T, L]
    assert not mask[:2].any()  # round 0: random, and no graph yet
    # a stored plan is a prefix of waypoints, each a landmark of the graph it was planned on
    # (round 2's graph; rounds 1 and 2 each built one: compare only round 2's episodes)
    assert np.all(mask[..., 1:] <= mask[..., :-1])
    for wp in goals[4:6][mask[4:6]]:
        assert np.any(np.all(np.isclose(landmarks, wp), axis=-1))
    ev = jax.tree.map(np.asarray, evaluate(carry, jax.random.split(jax.random.key(1), 1)))
    assert np.isfinite(ev["final_goal_distance"]).all() and ev["eval_path_length"] >= 0
