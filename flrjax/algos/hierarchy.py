"""The hierarchy DHRL, PIG and HIGL share: the goal-conditioned low level, DHRL's landmark
graph, and the skeleton of an episode round.

The low level (:mod:`flrjax.agents.gc_td3`) acts in ``num_envs`` lockstep envs, stores every
step in an episode-ring HER buffer and learns from HER batches with eq. (1)'s sparse reward or,
with ``cfg.flr``, the forward-looking reward (:mod:`flrjax.algos.flr`); its distance critics
weigh the edges of the landmark graph (:mod:`flrjax.planner`). An episode round
(:func:`start_round`) is random during the initial rollouts and learning after; the graph is
rebuilt on its schedule (:func:`refresh_graph`); the round's env steps are scanned by
:func:`rollout.train`, each step making the critics' updates and each group of steps the
actor's (:func:`actor_catch_up`); the high level, if any, chooses a subgoal at the start of
each subgoal period, and at its end stores one transition and learns from it
(:func:`store_high`, :func:`learn_high`). Without a high level (``flat``) the low level chases
the episode's final goal, in training and in evaluation (:func:`evaluate`). The flags these
methods share are in :mod:`flrjax.algos.hierarchy_flags`, the low level's batches and rewards
in :mod:`flrjax.algos.low_batches`.

Reference: jayLEE0301/dhrl_official (``dhrl.py`` = ``DHRL/rl/algo/dhrl.py``, ``graph.py`` =
``DHRL/rl/algo/graph.py``, ``replay.py`` = ``DHRL/rl/replay/planner.py``, ``main.py`` =
``DHRL/main.py``, ``AntMaze.sh`` = ``scripts/AntMaze.sh``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State

from flrjax import planner, replay
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value
from flrjax.algos import flr, hierarchy_flags, rollout
from flrjax.algos.common import (
    BaseConfig,
    Run,
    base_fields,
    td3_config,
    td3_hparams,
)
from flrjax.algos.low_batches import REWARD_STATS
from flrjax.algos.onset import BUILD_STATS, build_stats
from flrjax.envs.maze import Maze
from flrjax.metric_names import scoped


@dataclasses.dataclass(frozen=True)
class HierarchyConfig(BaseConfig):
    """What the shared hierarchy needs from the run (static). Defaults: AntMaze.sh / main.py
    (``initial_episodes``: main.py --n_initial_rollouts 200, random subgoals and actions)."""

    low: gc_td3.TD3Config
    high: gc_td3.TD3Config  # see high_config()
    # The point's values of each level's traced numbers (the agents' states carry them).
    low_hp: gc_td3.Hparams
    high_hp: gc_td3.Hparams  # see high_hparams()
    subgoal_freq: int = 40  # --subgoal_freq
    high_optimize_freq: int = 10  # --high_optimize_freq: one high update per 10 env steps
    initial_sample: int = planner.INITIAL_SAMPLE  # --initial_sample 6000
    max_nodes: int = planner.N_GRAPH_NODE  # --n_graph_node 300
    stop_eps: float = planner.LOW_BOUND_EPSILON  # --low_bound_epsilon 10
    cutoff: float = planner.CUTOFF  # --cutoff 30
    max_path_len: int = 32  # waypoints kept per plan (the reference's list is unbounded)
    reach_eps: float = planner.REACH_EPS  # graph.py get_waypoint: 0.5
    graph_start_round: int = 0  # first episode round that starts with a fresh graph
    graph_every: int = 1  # rounds between rebuilds
    flr: flr.FLRConfig | None = None  # None: the sparse reward of eq. (1) (plain DHRL)

    @property
    def high_updates_per_period(self) -> int:
        """High-level updates per subgoal period: one per ``high_optimize_freq`` low-level
        updates, the reference's ratio (one per 10 env steps at one update per env step)."""
        ratio = self.subgoal_freq * self.updates_per_iter // self.high_optimize_freq
        return max(self.high.actor_update_freq, ratio)  # at least one actor step per period


def _box(bounds: tuple) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(half-extent, centre) of the maze's free bounding box."""
    lo, hi = (tuple(float(x) for x in b) for b in bounds)
    return (tuple((h - lo_) / 2 for lo_, h in zip(lo, hi, strict=True)),
            tuple((h + lo_) / 2 for lo_, h in zip(lo, hi, strict=True)))


def high_config(low: gc_td3.TD3Config, bounds: tuple, **overrides) -> gc_td3.TD3Config:
    """The high level's static TD3 (agent.py ``HighAgent``, learn.py ``HighLearner``).

    Subgoals ``tanh(.) * scale + offset`` over the maze's free bounding box (AntMaze.sh
    ``--subgoal_scale 12 --subgoal_offset 8``: [-4, 20]^2 in the U-maze), absolute final goal
    as input; HER relabels goals within 15 high steps; its critic bootstraps through every
    transition and has no horizon, whatever the low level's value reading (``reach_ends``,
    ``horizon``, ``n_step``); its critic is scalar (``critic_atoms``) and its inputs raw
    (``obs_norm``).
    """
    scale, offset = _box(bounds)
    kw = dict(action_max=scale, action_offset=offset, absolute_goal=True, future_step=15,
              reach_ends=False, horizon=None, n_step=1, critic_atoms=0, obs_norm=False)
    return dataclasses.replace(low, **{**kw, **overrides})


def high_hparams(low: gc_td3.Hparams, bounds: tuple,
                 subgoal_noise_eps: float = hierarchy_flags.SUBGOAL_NOISE_EPS,
                 **overrides: float) -> gc_td3.Hparams:
    """The high level's traced numbers: the low level's (gamma, Polyak, learning rates unless
    ``overrides`` say otherwise) with no action L2 and no random actions; Gaussian subgoal
    noise of std ``subgoal_noise_eps`` (``--subgoal_noise_eps``, 2) in maze units along the
    larger half-extent of the box (``noise_eps * action_max``); target smoothing 0.05 in
    subgoal units; HER relabels every goal (``future_p`` 1)."""
    scale, _ = _box(bounds)
    kw = dict(action_l2=0.0, noise_eps=subgoal_noise_eps / max(scale), random_eps=0.0,
              target_noise=0.05, future_p=1.0)
    return low.updated(**{**kw, **overrides})


def from_run(run: Run, env: Env, cls: type = HierarchyConfig, *, low_value: str = "infinite",
             n_step: int = 1, critic_atoms: int = 0, high_hp: dict | None = None, **fields):
    """The run's flags as a ``cls`` (a :class:`HierarchyConfig`) with ``fields``: budgets,
    both levels' TD3 (:func:`high_config`; the low level's value reading ``low_value``, its
    TD target's ``n_step`` and its main critics' ``critic_atoms``) and traced numbers
    (:func:`high_hparams`, with ``high_hp`` in place of the low level's, e.g.
    :func:`hierarchy_flags.high_numbers`), and the graph's schedule in episode rounds."""
    d = hierarchy_flags.settings(run)
    per_round = run.num_envs * run.horizon
    low = td3_config(run, future_step=d["low_future_step"],
                     reach_ends=low_value == "reach_ends",
                     horizon=d["subgoal_freq"] if low_value == "k_step" else None,
                     n_step=n_step, critic_atoms=critic_atoms)
    high = high_config(low, env.maze.bounds, future_step=run.horizon // d["subgoal_freq"])
    low_hp = td3_hparams(run)
    return cls(
        **base_fields(run, env), low=low, high=high, low_hp=low_hp,
        high_hp=high_hparams(low_hp, env.maze.bounds, **(high_hp or {})),
        subgoal_freq=d["subgoal_freq"],
        initial_sample=d["landmark_sample"], max_nodes=d["max_landmarks"],
        stop_eps=d["landmark_eps"], cutoff=d["cutoff"],
        graph_start_round=-(-d["graph_start_steps"] // per_round),
        graph_every=max(1, round(d["graph_every_steps"] / per_round)), **fields)


def hparams(cfg: HierarchyConfig) -> dict[str, gc_td3.Hparams]:
    """Both levels' traced numbers, as an ``init`` puts them in the agents' states."""
    return {"low": cfg.low_hp, "high": cfg.high_hp}


# --------------------------------------------------------------------------------------------
# The low level: acting and storing
# --------------------------------------------------------------------------------------------


def low_spec(env: Env) -> tuple[dict, dict]:
    """The low level's replay fields: per state, and per transition."""
    g = jax.ShapeDtypeStruct((2,), jnp.float32)
    states = {"obs": jax.ShapeDtypeStruct((env.observation_size,), jnp.float32),
              "achieved_goal": g, "torso_z": jax.ShapeDtypeStruct((), jnp.float32),
              "fallen": jax.ShapeDtypeStruct((), jnp.bool_)}
    return states, {"action": jax.ShapeDtypeStruct((env.action_size,), jnp.float32), "goal": g,
                    "final_goal": g}


def high_spec(env: Env, **transitions) -> tuple[dict, dict]:
    """The high level's replay fields: (obs, achieved goal) per state; the subgoal, the final
    goal and ``transitions`` per transition."""
    g = jax.ShapeDtypeStruct((2,), jnp.float32)
    states = {"obs": jax.ShapeDtypeStruct((env.observation_size,), jnp.float32),
              "achieved_goal": g}
    return states, {"action": g, "goal": g, **transitions}


def state_fields(s: State) -> dict:
    return {"obs": s.obs, "achieved_goal": s.info["achieved_goal"], "torso_z": s.info["torso_z"],
            "fallen": s.info["fallen"]}


def act_and_store(low: gc_td3.AgentState, env: Env, env_state: State, goal: jax.Array,
                  t: jax.Array, low_buffer: replay.ReplayState, keys: jax.Array,
                  random_phase: jax.Array) -> tuple[State, replay.ReplayState, jax.Array]:
    """One low-level env step of every env towards ``goal`` (uniform random actions during the
    initial rollouts, the exploring policy after), stored at time ``t`` with the episode's
    final goal. ``keys``: the policy's noise key and the random actions' key. Returns the next
    states, the buffer and the actions. With a horizon (:attr:`gc_td3.TD3Config.horizon`, the
    subgoal period) the policy sees the period's steps left."""
    k_act, k_rand = keys
    n = env_state.obs.shape[0]
    k = low.config.horizon
    left = None if k is None else k - t % k
    with jax.named_scope("act"):
        action = jnp.where(random_phase,
                           jax.random.uniform(k_rand, (n, env.action_size), minval=-1.0),
                           gc_td3.act(low, env_state.obs, goal, k_act, explore=True,
                                      steps_left=left))
    with jax.named_scope("physics"):
        nxt = jax.vmap(env.step)(env_state, action)
    with jax.named_scope("replay_insert"):
        low_buffer = replay.insert_step(low_buffer, t, {
            **state_fields(env_state), "action": action, "goal": goal,
            "final_goal": env_state.info["goal"]})
        low_buffer = replay.insert_final(low_buffer, state_fields(nxt))
    return nxt, low_buffer, action


def low_policy(low: gc_td3.AgentState, key: jax.Array, subgoal: jax.Array | None = None
               ) -> rollout.Policy:
    """The low level's deterministic policy (evaluation) towards ``subgoal``, or without a
    high level towards the episode's final goal; a scanned input is the steps left of its
    horizon (None: none)."""

    def policy(memory, s: State, left):
        goal = s.info["goal"] if subgoal is None else subgoal
        a = gc_td3.act(low, s.obs, goal, key, explore=False, steps_left=left)
        return memory, rollout.Decision(a, goal, goal)

    return policy


def evaluate(low: gc_td3.AgentState, key: jax.Array, env: Env, n: int, trace: bool,
             plan: rollout.Plan | None = None, period: int | None = None):
    """The hierarchy's deterministic episodes from :func:`rollout.start_states` (``n`` to the
    maze's goal, ``n`` to goals drawn as in training): the high level's ``plan`` at the start
    of every ``period`` steps, or without a high level the low level alone chasing the final
    goal. Returns the last states, the plans' and steps' outputs and the trace
    (:func:`rollout.unroll_periods`)."""
    s0 = rollout.start_states(env, key, n)
    steps = env.config.episode_length
    if plan is None:
        return rollout.unroll(env, s0, low_policy(low, key), steps, trace=trace)
    return rollout.unroll_periods(env, s0, plan, steps, period, trace=trace)


# --------------------------------------------------------------------------------------------
# The landmark graph (graph.py)
# --------------------------------------------------------------------------------------------


def dist_fn(low: gc_td3.AgentState, dot_dtype: Any = None, kernel: str = "xla"
            ) -> planner.DistFn:
    """The planner's distance: the low level's distance critics (agent.py ``_get_dist_*``),
    with ``dot_dtype`` matrix operands (:func:`gc_td3.distance`), by XLA or by the fused
    kernel (``kernel="fused"``, bf16 only: :func:`fused_value.distance`)."""
    if kernel == "fused":
        return functools.partial(fused_value.distance, low, dot_dtype=dot_dtype)
    return functools.partial(gc_td3.distance, low, dot_dtype=dot_dtype)


def graph_from_replay(low: gc_td3.AgentState, low_buffer: replay.ReplayState, key: jax.Array,
                      cfg: HierarchyConfig, maze: Maze) -> tuple[planner.Graph, dict]:
    """graph.py ``graph_construct``: ``initial_sample`` replay states (no HER), FPS from the
    first of them, critic distances between the landmarks, Floyd-Warshall; with the graph's
    and its sample's and replay's :func:`build_stats` in ``maze``."""
    data = replay.sample(low_buffer, key, cfg.initial_sample, future_p=0.0)
    graph, pdist = planner.graph_with_distances(
        0, dist_fn(low), data["obs"], data["achieved_goal"], max_nodes=cfg.max_nodes,
        stop_eps=cfg.stop_eps, cutoff=cfg.cutoff)
    return graph, build_stats(graph, pdist, maze, data["achieved_goal"], low_buffer)


def find_paths(low: gc_td3.AgentState, graph: planner.Graph, obs: jax.Array, subgoal: jax.Array,
               cfg: HierarchyConfig) -> planner.Path:
    """graph.py ``find_path`` for every env (``obs[E, o]``, ``subgoal[E, 2]``). On a graph with
    no landmark (before the first build) every path is empty: the low level chases the
    subgoal, as the reference does while ``graph is None``."""
    return jax.vmap(lambda o, sg: planner.find_path(
        graph, dist_fn(low), o, sg, cutoff=cfg.cutoff, max_path_len=cfg.max_path_len))(
        obs, subgoal)


# --------------------------------------------------------------------------------------------
# The low level: rewards and learning
# --------------------------------------------------------------------------------------------


def learn_low_critics(learning: jax.Array, low: gc_td3.AgentState, sample: Callable,
                      sample_g: Callable, key: jax.Array, cfg: HierarchyConfig
                      ) -> tuple[gc_td3.AgentState, dict]:
    """One env step's ``updates_per_iter`` updates of the main and distance critics, with
    their losses and Q (``low/``) and :data:`REWARD_STATS` (``stats/``)."""
    low, m = gc_td3.learn_if(learning, low, sample, key,
                             ("critic_loss", "q", "critic_g_loss", *REWARD_STATS),
                             critic_updates=cfg.updates_per_iter, actor_updates=0,
                             sample_g=sample_g)
    stats = {k: m.pop(k) for k in REWARD_STATS}
    return low, {**scoped("low", m), **scoped("stats", stats)}


# --------------------------------------------------------------------------------------------
# The episode round
# --------------------------------------------------------------------------------------------


class Round(NamedTuple):
    """What an episode round does: act at random (the initial rollouts) or learn, and how the
    updates are grouped (:func:`gc_td3.schedule`)."""

    random_phase: jax.Array
    learning: jax.Array
    group: int  # env steps per actor catch-up
    actor_updates: int  # actor updates per group


def start_round(episode: jax.Array, cfg: HierarchyConfig) -> Round:
    """``episode`` is the round index, the same for every seed (not vmapped): rounds before
    ``initial_episodes / num_envs`` act at random and skip updates, as the reference's initial
    rollouts do."""
    group, actor_updates = gc_td3.schedule(cfg.updates_per_iter, cfg.low.actor_update_freq)
    random_phase = episode * cfg.num_envs < cfg.initial_episodes
    return Round(random_phase, ~random_phase, group, actor_updates)


def refresh_graph(episode: jax.Array, cfg: HierarchyConfig,
                  build: Callable[[], tuple[planner.Graph, dict]], graph: planner.Graph
                  ) -> tuple[planner.Graph, dict]:
    """``build()`` (a graph and its :func:`build_stats`) on the rounds
    that start with a fresh graph (``graph_start_round`` and every ``graph_every`` after it),
    else ``graph`` and NaN stats (the round had no rebuild to judge)."""
    rebuild = (episode >= cfg.graph_start_round) & (
        (episode - cfg.graph_start_round) % cfg.graph_every == 0)
    no_stats = {k: jnp.float32(jnp.nan) for k in BUILD_STATS}
    with jax.named_scope("graph_build"):
        return jax.lax.cond(rebuild, build, lambda: (graph, no_stats))


def actor_catch_up(rnd: Round, actor_sampler: Callable,
                   names: tuple[str, ...] = ("actor_loss",),
                   actor_extra: gc_td3.ActorExtra | None = None) -> rollout.AfterGroup:
    """The hook after each group of env steps (:func:`rollout.train`; the carry ends with
    ``(buffer, agent, key)``): the actor's updates on ``actor_sampler(buffer)``, with
    ``actor_extra``'s term in the actor loss if given; their metrics in ``low/``."""

    def after(c):
        *rest, buffer, agent, key = c
        key, k_upd = jax.random.split(key)
        agent, m = gc_td3.learn_if(rnd.learning, agent, actor_sampler(buffer), k_upd, names,
                                   critic_updates=0, actor_updates=rnd.actor_updates,
                                   actor_extra=actor_extra)
        return (*rest, buffer, agent, key), scoped("low", m)

    return after


def store_high(high_buffer: replay.ReplayState, p: jax.Array, start: State, end: State,
               subgoal: jax.Array, **transitions) -> replay.ReplayState:
    """The high level's transition of period ``p``: from ``start`` with ``subgoal`` towards
    the final goal, to ``end``."""
    high_buffer = replay.insert_step(high_buffer, p, {
        "obs": start.obs, "achieved_goal": start.info["achieved_goal"], "action": subgoal,
        "goal": start.info["goal"], **transitions})
    return replay.insert_final(high_buffer, {
        "obs": end.obs, "achieved_goal": end.info["achieved_goal"]})


def learn_high(learning: jax.Array, high: gc_td3.AgentState, sample: Callable, key: jax.Array,
               cfg: HierarchyConfig, names: tuple[str, ...] = ("critic_loss", "q", "actor_loss"),
               **kw) -> tuple[gc_td3.AgentState, dict]:
    """A subgoal period's high-level updates (:attr:`HierarchyConfig.high_updates_per_period`),
    their metrics in ``high/``."""
    with jax.named_scope("high_level"):
        high, m = gc_td3.learn_if(learning, high, sample, key, names,
                                  critic_updates=cfg.high_updates_per_period,
                                  actor_updates=cfg.high_updates_per_period
                                  // cfg.high.actor_update_freq, **kw)
    return high, scoped("high", m)


def round_metrics(metrics: dict, env_state: State, graph: planner.Graph | None = None
                  ) -> dict:
    """The round's means, with its training success, physics resets and graph size (if it has
    a graph)."""
    metrics = jax.tree.map(jnp.mean, metrics)
    metrics["stats/train_success"] = env_state.info["success"].mean()
    metrics["stats/physics_resets"] = env_state.info["physics_resets"].sum().astype(jnp.float32)
    if graph is not None:
        metrics["stats/graph_nodes"] = graph.landmarks.mask.sum().astype(jnp.float32)
    return metrics

