"""``--algo dhrl``: DHRL (Lee et al., 2022) as pure functions inside the scanned, vmapped step.

A high-level TD3 policy proposes a subgoal every ``subgoal_freq`` env steps; a graph of
landmarks (farthest-point samples of the low-level replay, edges from the low level's distance
critics) turns it into waypoints; the goal-conditioned low level chases them with HER and the
sparse reward (or, for ``flr_dhrl``, the forward-looking reward). The low level, the graph and
the round's skeleton are :mod:`flrjax.algos.hierarchy`; this module is DHRL's high level, its
subgoal testing and the waypoint follower. Everything the reference does in Python between env
steps runs here inside ``lax.scan``: the graph rebuild is a ``lax.cond`` on the (unbatched)
episode index, planning a batched :func:`planner.find_path` per env at each subgoal.

One seed's state is a :class:`Carry`; :func:`train_episode` runs one lockstep episode of all
``num_envs`` envs as subgoal periods of env steps (:func:`rollout.train`: DHRL supplies the
low level's step and the high level's choice and learning around each period), and
:func:`evaluate` runs the deterministic hierarchy (with the planner) to the evaluation goal.

Reference: jayLEE0301/dhrl_official (``dhrl.py`` = ``DHRL/rl/algo/dhrl.py``, ``graph.py`` =
``DHRL/rl/algo/graph.py``, ``replay.py`` = ``DHRL/rl/replay/planner.py``, ``main.py`` =
``DHRL/main.py``, ``AntMaze.sh`` = ``scripts/AntMaze.sh``); our reading of it is in
``docs/reference/dhrl.md``. Deviations, and why:

- the reference's epoch (15 episodes of one env, then a graph rebuild) becomes ``graph_every``
  rounds of ``num_envs`` lockstep episodes; the first graph is built after the same number of
  env steps (``graph_start_steps``);
- a new episode enters the replay at its end in both (so updates during an episode sample
  older episodes), but here ``num_envs`` episodes arrive at once;
- the high level updates at each subgoal boundary (where its new transitions have just been
  made), once per ``high_optimize_freq`` low-level updates: the reference's ratio (one per 10
  env steps, at one low update per env step), kept when ``--updates-per-step`` changes the
  ratio of updates to data;
- the waypoint follower and the subgoal are reset at every subgoal boundary and at episode
  start, as in the reference (600 % 40 == 0, so its ``curr_subgoal`` carry-over between
  episodes has no effect);
- subgoal testing (``replay.py sample_her_transitions_with_subgoaltesting``) keeps the
  proposed subgoal on the first ``round(subgoal_test_p * B)`` samples of each batch instead of
  a Bernoulli draw per sample (samples are i.i.d., so the batch is the same in law up to the
  count), which keeps the landmark-distance penalty a fixed-shape batched call.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State
from flax import struct

from flrjax import networks, planner, replay, rewards
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value
from flrjax.algos import flr, hierarchy, hierarchy_flags, low_batches, onset, rollout
from flrjax.algos.common import HEROptions, Run, reset_envs
from flrjax.algos.registry import Method, register
from flrjax.metric_names import scoped
from flrjax.options import flag


@dataclasses.dataclass(frozen=True)
class DHRLConfig(hierarchy.HierarchyConfig):
    """The shared hierarchy's settings and DHRL's subgoal testing (AntMaze.sh / main.py)."""

    subgoal_test_p: float = 0.2  # --subgoaltest_p
    subgoal_test_threshold: float = 1.0  # --subgoaltest_threshold
    subgoal_test_penalty: float = 1.3  # replay.py: hard-coded penalty
    gradual_penalty: float = 5.0  # --gradual_pen: subgoal > 3 * cutoff from every landmark
    # Matrix operands of subgoal testing's landmark-to-subgoal distances (networks.PRECISIONS):
    # only compared with 3 * cutoff, so bf16 does; on a GPU the trainer's default
    # (SUBGOAL_TEST_GPU_PRECISION), float32 elsewhere.
    subgoal_test_precision: str = "float32"
    # "fused": those distances in one Pallas kernel (gc_td3.fused_value, bf16 only), all
    # landmarks at once; "xla": XLA's kernels, ``planner.PAIRWISE_ROWS`` landmarks at a time.
    subgoal_test_kernel: str = "xla"


#: Subgoal testing's precision on a GPU unless --subgoal-test-precision says otherwise: its
#: 300 landmarks x 205 tested subgoals per high-level update cost as much as eq. 5's
#: candidates, and are read only through a threshold on their min (docs/benchmarks.md).
SUBGOAL_TEST_GPU_PRECISION = "bfloat16"


@dataclasses.dataclass(frozen=True)
class DHRLOptions(HEROptions, hierarchy_flags.HighOptions, hierarchy_flags.GraphOptions,
                  hierarchy_flags.LowValueOptions, hierarchy_flags.KernelOptions):
    """DHRL's flags: the low level's HER and value reading, the high level's learning rates,
    the graph, the evaluation kernel, and subgoal testing's precision."""

    subgoal_test_precision: str | None = flag(
        None, "matrix operands of subgoal testing's landmark distances, float32 or bfloat16 "
              "(float32 accumulation; default: bfloat16 on a GPU, float32 on a CPU)",
        hierarchy_flags.GRAPH, type=str, choices=networks.PRECISIONS)


@dataclasses.dataclass(frozen=True)
class FLRDHRLOptions(DHRLOptions, flr.FLROptions):
    """FLR+DHRL's flags: DHRL's and the forward-looking reward's."""


def from_run(run: Run, env: Env) -> DHRLConfig:
    """The run's flags as DHRL's config: the shared hierarchy's, and subgoal testing's
    precision (:data:`SUBGOAL_TEST_GPU_PRECISION` on a GPU unless set) and kernel
    (:func:`fused_value.choose`)."""
    precision = _subgoal_test_precision(run)
    return hierarchy.from_run(
        run, env, DHRLConfig, low_value=run.low_value, n_step=run.n_step,
        critic_atoms=run.critic_atoms,
        high_hp=hierarchy_flags.high_numbers(run),
        subgoal_test_precision=precision,
        subgoal_test_kernel=fused_value.choose(run.value_kernel, precision, run.hidden,
                                               run.critic_layer_norm))


def from_run_flr(run: Run, env: Env) -> DHRLConfig:
    """FLR+DHRL's config: DHRL's with the forward-looking reward."""
    return dataclasses.replace(from_run(run, env), flr=flr.from_run(run))


def _subgoal_test_precision(run: Run) -> str:
    return hierarchy_flags.gpu_default(run.subgoal_test_precision, SUBGOAL_TEST_GPU_PRECISION)


def validate(run: Run, points: list[dict], env: Env) -> None:
    """The graph's flags and the kernel's needs."""
    hierarchy_flags.validate(run)
    hierarchy_flags.validate_kernel(run, {"subgoal_test_precision": _subgoal_test_precision(run)})


def validate_flr(run: Run, points: list[dict], env: Env) -> None:
    """FLR's settings, the graph's flags, and the kernel's needs for eq. 5 and subgoal
    testing."""
    flr.validate(run, points, env)
    hierarchy_flags.validate(run)
    hierarchy_flags.validate_kernel(run, {
        "flr_precision": hierarchy_flags.gpu_default(run.flr_precision,
                                               flr.FLR_GPU_DEFAULTS["flr_precision"]),
        "subgoal_test_precision": _subgoal_test_precision(run)})


def resolved(cfg: DHRLConfig) -> dict:
    """The updates', eq. 5's and subgoal testing's settings whose defaults follow the
    device."""
    return {"train_precision": cfg.low.train_precision,
            **(flr.resolved(cfg.flr) if cfg.flr is not None else {}),
            "subgoal_test_precision": cfg.subgoal_test_precision,
            "subgoal_test_kernel": cfg.subgoal_test_kernel}


hparams = hierarchy.hparams


@struct.dataclass
class Carry:
    env_state: State  # [num_envs]
    low_buffer: replay.ReplayState
    high_buffer: replay.ReplayState
    low: gc_td3.AgentState
    high: gc_td3.AgentState
    graph: planner.Graph
    key: jax.Array


def init(key: jax.Array, env: Env, cfg: DHRLConfig, hp: dict | None = None) -> Carry:
    """A fresh seed: both agents (with ``hp``, default :func:`hparams`), empty buffers, no
    graph, ``num_envs`` envs reset."""
    k_low, k_high, k_env, k_carry = jax.random.split(key, 4)
    obs = env.observation_size
    hp = hparams(cfg) if hp is None else hp
    low = gc_td3.init(k_low, obs, 2, env.action_size, cfg.low, hp["low"])
    high = gc_td3.init(k_high, obs, 2, 2, cfg.high, hp["high"])
    horizon = env.config.episode_length
    low_buffer = replay.init(cfg.buffer_episodes, horizon, cfg.num_envs,
                             *hierarchy.low_spec(env))
    high_buffer = replay.init(cfg.buffer_episodes, horizon // cfg.subgoal_freq, cfg.num_envs,
                              *hierarchy.high_spec(env))
    env_state = reset_envs(env, k_env, cfg.num_envs)
    return Carry(env_state=env_state, low_buffer=low_buffer, high_buffer=high_buffer, low=low,
                 high=high, graph=planner.empty_graph(cfg.max_nodes, obs, 2), key=k_carry)


# --------------------------------------------------------------------------------------------
# The high level: subgoals and subgoal testing
# --------------------------------------------------------------------------------------------


def _random_subgoal(key: jax.Array, n: int, cfg: DHRLConfig) -> jax.Array:
    """dhrl.py ``get_actions(random_goal=True)``: uniform over the subgoal box."""
    scale, offset = jnp.asarray(cfg.high.action_max), jnp.asarray(cfg.high.action_offset)
    return offset + scale * jax.random.uniform(key, (n, 2), minval=-1.0)


def _new_subgoal(c_high: gc_td3.AgentState, env_state: State, key: jax.Array,
                 random_phase: jax.Array, explore: bool, cfg: DHRLConfig) -> jax.Array:
    """dhrl.py ``get_actions`` at a subgoal boundary: random during the initial rollouts, else
    the high-level actor on (obs, final goal), with noise and clipping when exploring."""
    k_act, k_rand = jax.random.split(key)
    proposed = gc_td3.act(c_high, env_state.obs, env_state.info["goal"], k_act, explore=explore)
    return jnp.where(random_phase, _random_subgoal(k_rand, env_state.obs.shape[0], cfg),
                     proposed)


def high_batch(buffer: replay.ReplayState, dist_fn: planner.DistFn, graph: planner.Graph,
               high: gc_td3.AgentState, key: jax.Array, cfg: DHRLConfig) -> dict:
    """replay.py ``sample_her_transitions_with_subgoaltesting``: every goal relabelled to a
    future achieved goal within ``future_step`` high steps; the subgoal replaced by the
    achieved goal of the next high step except on the test samples (the first
    ``round(subgoal_test_p * B)``), which keep theirs and get ``-penalty`` if it was missed by
    more than ``subgoal_test_threshold``, or ``-gradual_penalty`` if it lies farther than
    ``3 * cutoff`` from every landmark of the current graph."""
    b = cfg.high.batch_size
    batch = replay.sample(buffer, key, b, future_p=high.hp.future_p,
                          future_step=cfg.high.future_step)
    n_test = round(cfg.subgoal_test_p * b)
    test = jnp.arange(b) < n_test
    reached = batch["next_achieved_goal"]
    action = jnp.where(test[:, None], batch["action"], reached)
    reward = rewards.sparse_reward(reached, batch["goal"], delta=cfg.delta)
    missed = jnp.linalg.norm(action - reached, axis=-1) > cfg.subgoal_test_threshold
    reward = jnp.where(test & missed, -cfg.subgoal_test_penalty, reward)
    lm = graph.landmarks
    # d[n, k]: landmark k -> tested subgoal n, in row blocks, so that the temporaries do not
    # hold all pairs at once; the fused kernel
    # keeps its activations on chip and takes them all at once.
    rows = lm.state.shape[0] if cfg.subgoal_test_kernel == "fused" else planner.PAIRWISE_ROWS
    d = planner.pairwise_distance(dist_fn, lm.state, batch["action"][:n_test], rows).T
    far = (planner.graph_to_goal_distance(graph, d) > 3 * cfg.cutoff) & lm.mask.any()
    far = jnp.concatenate([far, jnp.zeros((b - n_test,), bool)])
    reward = jnp.where(test & far, -cfg.gradual_penalty, reward)
    return {**batch, "action": action, "reward": reward}


# --------------------------------------------------------------------------------------------
# Following the waypoints (graph.py get_waypoint)
# --------------------------------------------------------------------------------------------


def _followers(n: int) -> planner.FollowerState:
    """``n`` fresh waypoint followers, one per env (set with every new path)."""
    return jax.vmap(lambda _: planner.follower_init())(jnp.arange(n))


def _follow(follower: planner.FollowerState, path: planner.Path, s: State, subgoal: jax.Array,
            cfg: DHRLConfig) -> tuple[planner.FollowerState, jax.Array]:
    """Every env's step along its path: the followers and the waypoints to chase."""
    return jax.vmap(functools.partial(planner.advance, reach_eps=cfg.reach_eps))(
        follower, path, s.info["achieved_goal"], subgoal)


# --------------------------------------------------------------------------------------------
# Training and evaluation
# --------------------------------------------------------------------------------------------


def train_episode(carry: Carry, episode: jax.Array, env: Env, cfg: DHRLConfig
                  ) -> tuple[Carry, dict]:
    """One round of ``num_envs`` lockstep episodes (dhrl.py ``collect_experience`` with
    training), preceded by a graph rebuild on the rounds that have one. ``episode`` is the
    round index, the same for every seed (not vmapped). :func:`rollout.train` scans the low
    level's steps (following the waypoints towards the subgoal) in the high level's subgoal
    periods."""
    rnd = hierarchy.start_round(episode, cfg)
    key, k_graph, k_reset = jax.random.split(carry.key, 3)
    graph, graph_m = hierarchy.refresh_graph(episode, cfg, lambda: hierarchy.graph_from_replay(
        carry.low, carry.low_buffer, k_graph, cfg, env.maze), carry.graph)
    env_state = reset_envs(env, k_reset, cfg.num_envs)

    def env_step(c, t):
        env_state, follower, path, subgoal, low_buffer, low, key = c
        key, k_act, k_upd = jax.random.split(key, 3)
        follower, waypoint = _follow(follower, path, env_state, subgoal, cfg)
        nxt, low_buffer, _ = hierarchy.act_and_store(low, env, env_state, waypoint, t,
                                                     low_buffer, jax.random.split(k_act),
                                                     rnd.random_phase)
        sample, sample_g, _ = low_batches.low_samplers(low_buffer, cfg)
        low, m = hierarchy.learn_low_critics(rnd.learning, low, sample, sample_g, k_upd, cfg)
        return (nxt, follower, path, subgoal, low_buffer, low, key), (m, None)

    def choose(c, p):
        env_state, low_buffer, _, low, high, key = c
        key, k_sg, k_high = jax.random.split(key, 3)
        with jax.named_scope("plan"):
            subgoal = _new_subgoal(high, env_state, k_sg, rnd.random_phase, True, cfg)
            path = hierarchy.find_paths(low, graph, env_state.obs, subgoal, cfg)
        return ((env_state, _followers(cfg.num_envs), path, subgoal, low_buffer, low, key),
                (subgoal, path, k_high))

    def finish(c, low_c, context, p, m, _):
        env_state, _, high_buffer, _, high, _ = c
        nxt, _, _, _, low_buffer, low, key = low_c
        subgoal, path, k_high = context
        high_buffer = hierarchy.store_high(high_buffer, p, env_state, nxt, subgoal)
        test_dist = hierarchy.dist_fn(low, networks.dot_dtype(cfg.subgoal_test_precision),
                                      cfg.subgoal_test_kernel)
        sample_h = functools.partial(high_batch, high_buffer, test_dist, graph, cfg=cfg)
        high, m_high = hierarchy.learn_high(rnd.learning, high, sample_h, k_high, cfg)
        m = {**jax.tree.map(jnp.mean, m), **m_high, "stats/path_length": path.length.mean(),
             "stats/plan_found_frac": path.reaches_subgoal.mean(),
             **scoped("stats", onset.subgoal_stats(env.maze, env_state, nxt, subgoal))}
        return (nxt, low_buffer, high_buffer, low, high, key), m

    (env_state, low_buffer, high_buffer, low, high, key), metrics = rollout.train(
        env_step, hierarchy.actor_catch_up(rnd, lambda b: low_batches.low_samplers(b, cfg)[2]),
        (env_state, carry.low_buffer, carry.high_buffer, carry.low, carry.high, key),
        env.config.episode_length, rnd.group, rollout.High(cfg.subgoal_freq, choose, finish))
    metrics = hierarchy.round_metrics(metrics, env_state, graph)
    metrics.update(low_batches.reward_gap(metrics))
    metrics.update(scoped("stats", graph_m))
    carry = Carry(env_state=env_state, low_buffer=replay.finish_episodes(low_buffer),
                  high_buffer=replay.finish_episodes(high_buffer), low=low, high=high,
                  graph=graph, key=key)
    return carry, metrics


def evaluate(carry: Carry, key: jax.Array, env: Env, cfg: DHRLConfig, trace: bool = False):
    """Deterministic hierarchy with the planner (dhrl.py ``run_eval``), by
    :func:`hierarchy.evaluate`: ``eval_episodes`` from the start to ``env.maze.goal`` and as
    many to goals drawn as in training; at each subgoal period's start the high level's
    subgoal and a path to it, then the low level follows the path's waypoints. ``trace``: also
    every step's record (:func:`rollout.traced`)."""
    n = cfg.eval_episodes
    no = jnp.asarray(False)
    lefts = None if cfg.low.horizon is None else cfg.subgoal_freq - jnp.arange(cfg.subgoal_freq)

    def plan(s):
        subgoal = _new_subgoal(carry.high, s, key, no, False, cfg)
        path = hierarchy.find_paths(carry.low, carry.graph, s.obs, subgoal, cfg)

        def policy(follower, s, left):
            follower, waypoint = _follow(follower, path, s, subgoal, cfg)
            a = gc_td3.act(carry.low, s.obs, waypoint, key, explore=False, steps_left=left)
            return follower, rollout.Decision(a, waypoint, subgoal)

        return policy, _followers(2 * n), lefts, path.length[:n].mean()

    s, (path_len, _), rec = hierarchy.evaluate(carry.low, key, env, n, trace, plan,
                                               cfg.subgoal_freq)
    return rollout.report(s, n, rec, trace, {"eval/path_length": path_len.mean()})


def params(carry: Carry) -> tuple:
    """Both levels' trained parameters."""
    return gc_td3.trained(carry.low), gc_td3.trained(carry.high)


_FUNCTIONS = dict(hparams=hparams, init=init, train_episode=train_episode, evaluate=evaluate,
                  params=params, resolved=resolved, train_bf16_gpu=True)
register(Method("dhrl", "DHRL", DHRLOptions, from_run, validate=validate, **_FUNCTIONS))
register(Method("flr_dhrl", "FLR+DHRL", FLRDHRLOptions, from_run_flr, validate=validate_flr,
                with_runs=flr.with_runs, base="dhrl", base_point=(("flr_alpha", 0.0),),
                **_FUNCTIONS))
