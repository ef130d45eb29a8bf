"""A :class:`~flrjax.config.TrainConfig` translated into each method's own config, and the
metrics each method logs."""

from __future__ import annotations

import dataclasses

import jax

from flrjax.agents import gc_td3
from flrjax.algos import dhrl, flat, flr, hierarchy, higl, pig
from flrjax.config import (
    PIG_ALGOS,
    TrainConfig,
    dhrl_settings,
    flr_settings,
    make_env,
    run_value,
    sweep_points,
)

#: Evaluation metrics of every algorithm.
EVAL_FIELDS = ("success_rate", "final_goal_distance", "falls", "final_torso_z",
               "random_goal_success", "random_goal_distance")
#: Per algorithm: evaluation metrics beyond the common ones, then the training metrics.
ALGO_FIELDS = {
    "flat": ((), ("critic_loss", "q", "actor_loss", "train_success", "physics_resets")),
    "dhrl": (("eval_path_length",),
             ("critic_loss", "q", "critic_g_loss", "actor_loss", "high_critic_loss", "high_q",
              "high_actor_loss", "path_length", "graph_nodes", "reach_reward_upright",
              "reach_reward_fallen", "reward_gap", "reach_frac", "reach_fallen_frac",
              "flr_no_candidate_frac", "train_success", "physics_resets")),
}
ALGO_FIELDS["flr_dhrl"] = ALGO_FIELDS["dhrl"]
ALGO_FIELDS["higl"] = ((), (
    "critic_loss", "q", "actor_loss", "high_critic_loss", "high_q", "high_actor_loss",
    "landmark_loss", "adjacency_loss", "rnd_loss", "graph_nodes", "train_success",
    "physics_resets"))
ALGO_FIELDS["pig"] = ALGO_FIELDS["flr_pig"] = (
    ("eval_path_length", "eval_on_target_frac", "no_plan_success_rate", "no_plan_goal_distance"),
    ("critic_loss", "q", "critic_g_loss", "actor_loss", "imitation", "skip_prob", "planned_steps",
     "graph_nodes", "reach_reward_upright", "reach_reward_fallen", "reward_gap",
     "reach_frac", "reach_fallen_frac", "flr_no_candidate_frac", "train_success", "physics_resets"))


def metric_fields(algo: str) -> tuple[str, ...]:
    """Columns of ``metrics.csv`` for ``algo``: one row per seed and evaluation."""
    extra_eval, train_fields = ALGO_FIELDS[algo]
    return ("step", "seed", *EVAL_FIELDS, *extra_eval, *train_fields, "wall_time",
            "env_steps_per_s")


def csv_fields(cfg: TrainConfig) -> tuple[str, ...]:
    """Columns of ``cfg``'s ``metrics.csv``: :func:`metric_fields`, with the swept fields
    after ``seed``."""
    step, seed, *rest = metric_fields(cfg.algo)
    return (step, seed, *sweep_points(cfg)[0], *rest)


def td3_config(cfg: TrainConfig) -> gc_td3.TD3Config:
    return gc_td3.TD3Config(hidden_sizes=(cfg.hidden,) * 3, batch_size=cfg.batch_size,
                            polyak=cfg.polyak, target_update_freq=cfg.target_update_freq)


def flat_config(cfg: TrainConfig) -> flat.FlatConfig:
    return flat.FlatConfig(num_envs=cfg.num_envs, updates_per_iter=cfg.updates_per_iter,
                           buffer_episodes=cfg.buffer_episodes,
                           initial_episodes=cfg.initial_episodes,
                           eval_episodes=cfg.eval_episodes, delta=make_env(cfg).config.delta,
                           td3=td3_config(cfg))


def dhrl_config(cfg: TrainConfig) -> dhrl.DHRLConfig:
    d = dhrl_settings(cfg)
    env = make_env(cfg)
    per_round = cfg.num_envs * cfg.horizon
    low = dataclasses.replace(td3_config(cfg), future_step=d["low_future_step"])
    high = hierarchy.high_config(low, env.maze.bounds,
                            future_step=cfg.horizon // d["subgoal_freq"])
    return dhrl.DHRLConfig(
        num_envs=cfg.num_envs, updates_per_iter=cfg.updates_per_iter,
        buffer_episodes=cfg.buffer_episodes, initial_episodes=cfg.initial_episodes,
        eval_episodes=cfg.eval_episodes, delta=env.config.delta, low=low, high=high,
        subgoal_freq=d["subgoal_freq"], initial_sample=d["landmark_sample"],
        max_nodes=d["max_landmarks"], stop_eps=d["landmark_eps"], cutoff=d["cutoff"],
        graph_start_round=-(-d["graph_start_steps"] // per_round),
        graph_every=max(1, round(d["graph_every_steps"] / per_round)))


#: How the trainer evaluates eq. 5's candidate values on a GPU, unless flags say otherwise:
#: the whole batch in one call (fewer, larger matrix products) with bf16 matrix operands
#: (float32 accumulation and parameters: twice the tensor cores' rate). The reward is a max
#: over randomly drawn candidates; bf16 moves it by a fraction of what a new draw of the
#: candidates does (tests/algos/test_dhrl.py, docs/benchmarks.md). Elsewhere FLRConfig's
#: own: float32, the reaching transitions only, in chunks (on a CPU the FLOPs count).
FLR_GPU_DEFAULTS = dict(flr_value_chunk=0, flr_precision="bfloat16")


def flr_config(cfg: TrainConfig) -> flr.FLRConfig | None:
    """The FLR settings of an ``flr_*`` algo (None for the others)."""
    if not cfg.algo.startswith("flr_"):
        return None
    d = flr_settings(cfg)
    gpu = FLR_GPU_DEFAULTS if jax.default_backend() == "gpu" else {}
    chunk, precision = (gpu.get(k) if getattr(cfg, k) is None else getattr(cfg, k)
                        for k in ("flr_value_chunk", "flr_precision"))
    extra = {} if chunk is None else {"value_chunk": chunk or None}
    if precision is not None:
        extra["value_dtype"] = precision
    return flr.FLRConfig(alpha=d["flr_alpha"], eps=d["flr_eps"],
                          num_candidates=d["flr_candidates"], next_subgoal=d["flr_next"],
                          **extra)


#: PIG's imitation weight: train_antmaze.sh --lambda_goal_loss 0.001 on torques of +-30,
#: i.e. 0.001 * 30**2 on our actions in [-1, 1].
PIG_IMITATION_WEIGHT = 0.001 * 30.0**2


def higl_config(cfg: TrainConfig) -> higl.HIGLConfig:
    """HIGL (higl_ant_maze_u.sh / main.py): subgoals relative to the position every 10 steps
    (5 on the point mass) within the maze's half extent, manager noise 1 and target noise 0.2,
    controller discount 0.95 with the dense reward, plain Q critics (no distance
    parametrisation), no HER, graph edges under 38 (``--clip_v``)."""
    given = {k: getattr(cfg, k) for k in ("subgoal_freq", "cutoff") if getattr(cfg, k)}
    point = not cfg.env.startswith("ant")
    c = dataclasses.replace(cfg, **{"subgoal_freq": 5 if point else 10, "cutoff": 38.0,
                                    **given})
    base = dhrl_config(c)
    lo, hi = make_env(cfg).maze.bounds
    scale = tuple(float(h - lo_) / 2 for lo_, h in zip(lo, hi, strict=True))
    low = dataclasses.replace(base.low, gamma=0.95, dist_critic=False, clip_return=1e6,
                              future_p=0.0)
    high = dataclasses.replace(base.high, action_max=scale, action_offset=(0.0, 0.0),
                               noise_eps=1.0 / max(scale), target_noise=0.2,
                               dist_critic=False, clip_return=1e6, future_p=0.0)
    return higl.HIGLConfig(base=dataclasses.replace(base, low=low, high=high))


def algo_config(cfg: TrainConfig):
    """The algo's own config (of one sweep point: :func:`flrjax.runner.build` puts each run's
    values in)."""
    cfg = dataclasses.replace(cfg, **sweep_points(cfg)[0])
    if cfg.algo == "higl":
        return higl_config(cfg)
    if cfg.algo in ("dhrl", "flr_dhrl"):
        return dataclasses.replace(dhrl_config(cfg), flr=flr_config(cfg))
    if cfg.algo in PIG_ALGOS:
        base = dhrl_config(cfg)
        low = dataclasses.replace(base.low, imitation_weight=PIG_IMITATION_WEIGHT)
        return pig.PIGConfig(base=dataclasses.replace(base, low=low, flr=flr_config(cfg)),
                             jump_temp=run_value(cfg, "pig_jump_temp"))
    return flat_config(cfg)
