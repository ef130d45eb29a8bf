"""``--algo dhrl``: DHRL (Lee et al., 2022) as pure functions inside the scanned, vmapped step.

A high-level TD3 policy proposes a subgoal every ``subgoal_freq`` env steps; a graph of
landmarks (farthest-point samples of the low-level replay, edges from the low level's distance
critics) turns it into waypoints; the goal-conditioned low level (:mod:`flrjax.agents.gc_td3`)
chases them with HER and the sparse reward. Everything the reference does in Python between
env steps runs here inside ``lax.scan``: the graph rebuild is a ``lax.cond`` on the (unbatched)
episode index, planning a batched :func:`planner.find_path` per env at each subgoal.

One seed's state is a :class:`Carry`; :func:`train_episode` runs one lockstep episode of all
``num_envs`` envs as a scan over subgoal periods of a scan over env steps, and
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

from flrjax import planner, replay, rewards
from flrjax.agents import gc_td3
from flrjax.algos import evaluation

#: dhrl.py ``run``: ``n_cycles`` (15) episodes per epoch, of 600 steps with one env.
REFERENCE_EPOCH_STEPS = 15 * 600
#: dhrl.py ``run``: the first graph is built at the end of epoch ``start_planning_epoch + 1``
#: (6, zero-based), after 200 random episodes (120k steps) and 7 epochs (63k steps).
REFERENCE_GRAPH_START_STEPS = 200 * 600 + 7 * REFERENCE_EPOCH_STEPS


@dataclasses.dataclass(frozen=True)
class FLRConfig:
    """The forward-looking reward (paper eq. 5) on the low level's main critics.

    For a transition that reaches its (relabelled) subgoal, the reward is ``alpha`` times the
    best target-critic value ``V_l(s', sg')`` over ``num_candidates`` next subgoals sampled on
    the ring ``[eps, 1.25 eps]`` around the subgoal (:func:`rewards.sample_next_subgoals`,
    clipped to the subgoal box), or over the final goal with ``next_subgoal="goal"`` (the
    paper's Fig. 5 ablation). The paper: alpha 0.01 (= 1 - gamma), eps 2, delta 0.5.
    ``alpha = 0`` is plain DHRL: reaching pays eq. (1)'s 0. Inside a sweep, ``alpha``,
    ``eps`` and ``next_subgoal`` (then a bool, True for the goal) are traced per run.
    ``value_chunk``: V is evaluated only on the batch's reaching transitions, this many at a
    time (:func:`rewards.forward_looking_reward`'s ``chunk``; None: on all of them).
    The rewards are the same; the cost follows the fraction that reaches (one batch on the
    CPU: 12 ms at 11%, 35 at 31%, 69 at 70%, 91 at 100%, against 113-118 ms for all 1,024
    transitions; ``benchmarks/flr_cost.py``). On the H100 the figure runs' FLR cost fell 18%
    (63-73% of their batch reaches); their whole step took 22.0 ms at 128, 21.7 at 512 (means
    of three timings, spread +-0.4) and 23.9 on all transitions (``train_throughput.py
    --value-chunk``).
    """

    alpha: float = 0.01
    eps: float = 2.0
    num_candidates: int = 16
    next_subgoal: str = "sample"  # "sample" | "goal"
    value_chunk: int | None = 128
    # Matrix operands of the candidate values: "float32" (TF32 on GPUs that allow it) or
    # "bfloat16" (rounded operands, float32 accumulation; the parameters stay float32). On a
    # GPU the trainer's defaults are bfloat16 and the whole batch at once (methods.flr_config).
    value_dtype: str = "float32"


def next_is_goal(flr: FLRConfig) -> bool | jax.Array:
    """Whether the final goal is the next subgoal: from the name, or a sweep's traced bool."""
    return flr.next_subgoal == "goal" if isinstance(flr.next_subgoal, str) else flr.next_subgoal


@dataclasses.dataclass(frozen=True)
class DHRLConfig:
    """What DHRL needs from the run (static). Defaults: AntMaze.sh / main.py."""

    num_envs: int
    updates_per_iter: int
    buffer_episodes: int
    initial_episodes: int  # main.py --n_initial_rollouts 200: random subgoals and actions
    eval_episodes: int
    delta: float  # reward threshold (0.5)
    low: gc_td3.TD3Config
    high: gc_td3.TD3Config  # see high_config()
    subgoal_freq: int = 40  # --subgoal_freq
    high_optimize_freq: int = 10  # --high_optimize_freq: one high update per 10 env steps
    subgoal_test_p: float = 0.2  # --subgoaltest_p
    subgoal_test_threshold: float = 1.0  # --subgoaltest_threshold
    subgoal_test_penalty: float = 1.3  # replay.py: hard-coded penalty
    gradual_penalty: float = 5.0  # --gradual_pen: subgoal > 3 * cutoff from every landmark
    initial_sample: int = planner.INITIAL_SAMPLE  # --initial_sample 6000
    max_nodes: int = planner.N_GRAPH_NODE  # --n_graph_node 300
    stop_eps: float = planner.LOW_BOUND_EPSILON  # --low_bound_epsilon 10
    cutoff: float = planner.CUTOFF  # --cutoff 30
    max_path_len: int = 32  # waypoints kept per plan (the reference's list is unbounded)
    reach_eps: float = planner.REACH_EPS  # graph.py get_waypoint: 0.5
    graph_start_round: int = 0  # first episode round that starts with a fresh graph
    graph_every: int = 1  # rounds between rebuilds
    flr: FLRConfig | None = None  # None: the sparse reward of eq. (1) (plain DHRL)

    @property
    def high_updates_per_period(self) -> int:
        """High-level updates per subgoal period: one per ``high_optimize_freq`` low-level
        updates, the reference's ratio (one per 10 env steps at one update per env step)."""
        ratio = self.subgoal_freq * self.updates_per_iter // self.high_optimize_freq
        return max(self.high.actor_update_freq, ratio)  # at least one actor step per period


def high_config(low: gc_td3.TD3Config, bounds: tuple, **overrides) -> gc_td3.TD3Config:
    """The high level's TD3 (agent.py ``HighAgent``, learn.py ``HighLearner``).

    Subgoals ``tanh(.) * scale + offset`` over the maze's free bounding box (AntMaze.sh
    ``--subgoal_scale 12 --subgoal_offset 8``: [-4, 20]^2 in the U-maze), absolute final goal
    as input, no action L2 and no random actions; Gaussian subgoal noise of std 2
    (``--subgoal_noise_eps``) along the larger half-extent (``noise_eps * action_max``);
    target smoothing 0.05 in subgoal units; HER relabels every goal within 15 high steps.
    """
    lo, hi = (tuple(float(x) for x in b) for b in bounds)
    scale = tuple((h - lo_) / 2 for lo_, h in zip(lo, hi, strict=True))
    offset = tuple((h + lo_) / 2 for lo_, h in zip(lo, hi, strict=True))
    kw = dict(action_max=scale, action_offset=offset, absolute_goal=True, action_l2=0.0,
              noise_eps=2.0 / max(scale), random_eps=0.0, target_noise=0.05, future_p=1.0,
              future_step=15)
    return dataclasses.replace(low, **{**kw, **overrides})


@struct.dataclass
class Carry:
    env_state: State  # [num_envs]
    low_buffer: replay.ReplayState
    high_buffer: replay.ReplayState
    low: gc_td3.AgentState
    high: gc_td3.AgentState
    graph: planner.Graph
    key: jax.Array


def low_spec(env: Env) -> tuple[dict, dict]:
    g = jax.ShapeDtypeStruct((2,), jnp.float32)
    states = {"obs": jax.ShapeDtypeStruct((env.observation_size,), jnp.float32),
              "achieved_goal": g, "torso_z": jax.ShapeDtypeStruct((), jnp.float32),
              "fallen": jax.ShapeDtypeStruct((), jnp.bool_)}
    return states, {"action": jax.ShapeDtypeStruct((env.action_size,), jnp.float32), "goal": g,
                    "final_goal": g}


def _high_spec(env: Env) -> tuple[dict, dict]:
    g = jax.ShapeDtypeStruct((2,), jnp.float32)
    states = {"obs": jax.ShapeDtypeStruct((env.observation_size,), jnp.float32),
              "achieved_goal": g}
    return states, {"action": g, "goal": g}


def init(key: jax.Array, env: Env, cfg: DHRLConfig) -> Carry:
    """A fresh seed: both agents, empty buffers, no graph, ``num_envs`` envs reset."""
    k_low, k_high, k_env, k_carry = jax.random.split(key, 4)
    obs = env.observation_size
    low = gc_td3.init(k_low, obs, 2, env.action_size, cfg.low)
    high = gc_td3.init(k_high, obs, 2, 2, cfg.high)
    horizon = env.config.episode_length
    low_buffer = replay.init(cfg.buffer_episodes, horizon, cfg.num_envs, *low_spec(env))
    high_buffer = replay.init(cfg.buffer_episodes, horizon // cfg.subgoal_freq, cfg.num_envs,
                              *_high_spec(env))
    env_state = jax.vmap(env.reset)(jax.random.split(k_env, cfg.num_envs))
    return Carry(env_state=env_state, low_buffer=low_buffer, high_buffer=high_buffer, low=low,
                 high=high, graph=planner.empty_graph(cfg.max_nodes, obs, 2), key=k_carry)


# --------------------------------------------------------------------------------------------
# Graph and planning (graph.py)
# --------------------------------------------------------------------------------------------


def _dist_fn(low: gc_td3.AgentState) -> planner.DistFn:
    """The planner's distance: the low level's distance critics (agent.py ``_get_dist_*``)."""
    return functools.partial(gc_td3.distance, low)


def graph_from_replay(low: gc_td3.AgentState, low_buffer: replay.ReplayState, key: jax.Array,
                cfg: DHRLConfig) -> planner.Graph:
    """graph.py ``graph_construct``: ``initial_sample`` replay states (no HER), FPS from the
    first of them, critic distances between the landmarks, Floyd-Warshall."""
    data = replay.sample(low_buffer, key, cfg.initial_sample, future_p=0.0)
    return planner.graph_construct(0, _dist_fn(low), data["obs"], data["achieved_goal"],
                                   max_nodes=cfg.max_nodes, stop_eps=cfg.stop_eps,
                                   cutoff=cfg.cutoff)


def find_paths(low: gc_td3.AgentState, graph: planner.Graph, obs: jax.Array, subgoal: jax.Array,
         cfg: DHRLConfig) -> planner.Path:
    """graph.py ``find_path`` for every env (``obs[E, o]``, ``subgoal[E, 2]``). On a graph with
    no landmark (before the first build) every path is empty: the low level chases the
    subgoal, as the reference does while ``graph is None``."""
    return jax.vmap(lambda o, sg: planner.find_path(
        graph, _dist_fn(low), o, sg, cutoff=cfg.cutoff, max_path_len=cfg.max_path_len))(
        obs, subgoal)


def _random_subgoal(key: jax.Array, n: int, cfg: DHRLConfig) -> jax.Array:
    """dhrl.py ``get_actions(random_goal=True)``: uniform over the subgoal box."""
    scale, offset = jnp.asarray(cfg.high.action_max), jnp.asarray(cfg.high.action_offset)
    return offset + scale * jax.random.uniform(key, (n, 2), minval=-1.0)


# --------------------------------------------------------------------------------------------
# Learning
# --------------------------------------------------------------------------------------------


#: Training metrics of the low-level reward, summed over a batch (ratios are taken per
#: episode): reaching transitions from upright / fallen states and their rewards (Fig. 4b),
#: reaching transitions with no qualifying FLR candidate, and the transitions sampled.
REWARD_STATS = ("reach_up_n", "reach_up_reward", "reach_fall_n", "reach_fall_reward",
                "flr_no_candidate", "sampled_n")


def low_reward(agent: gc_td3.AgentState, batch: dict, key: jax.Array, cfg: DHRLConfig
               ) -> tuple[jax.Array, dict]:
    """The low level's reward of a HER batch and its :data:`REWARD_STATS`: eq. (1), or with
    ``cfg.flr`` eq. (5) labelled by the agent's *target* critics and actor
    (:func:`gc_td3.value`), the networks the TD target bootstraps from, so that the reward and
    the bootstrap value of a reached subgoal are on one scale and move slowly. V is clipped to
    ``[-1 / (1 - gamma), 0]`` so that eq. (4)'s ``reward >= -1`` holds for ``alpha <= 1 -
    gamma`` whatever the critic outputs."""
    flr = cfg.flr
    if flr is None:
        reward = rewards.sparse_reward(batch["next_achieved_goal"], batch["goal"],
                                       delta=cfg.delta)
        reached = reward == 0.0
        no_candidate = jnp.zeros_like(reached)
    else:
        # Both candidate sets, chosen per run: a sweep over --flr-next traces the choice.
        scale = jnp.asarray(cfg.high.action_max)
        offset = jnp.asarray(cfg.high.action_offset)
        sampled = rewards.sample_next_subgoals(
            key, batch["goal"], eps=flr.eps, num=flr.num_candidates, low=offset - scale,
            high=offset + scale)
        goal_next = next_is_goal(flr)
        candidates = jnp.where(goal_next, rewards.next_subgoal_is_goal(
            batch["final_goal"], flr.num_candidates), sampled)
        dot_dtype = None if flr.value_dtype == "float32" else jnp.dtype(flr.value_dtype)
        out = rewards.forward_looking_reward(
            functools.partial(gc_td3.value, agent, dot_dtype=dot_dtype), batch["next_obs"],
            batch["next_achieved_goal"], batch["goal"], candidates, alpha=flr.alpha,
            eps=jnp.where(goal_next, 0.0, flr.eps), delta=cfg.delta,
            v_min=-1.0 / (1.0 - cfg.low.gamma), chunk=flr.value_chunk)
        reward, reached = out.reward, out.reached
        no_candidate = reached & (out.num_qualified == 0)
    up, fall = reached & ~batch["next_fallen"], reached & batch["next_fallen"]
    stats = {"reach_up_n": up.sum(), "reach_up_reward": jnp.where(up, reward, 0.0).sum(),
             "reach_fall_n": fall.sum(), "reach_fall_reward": jnp.where(fall, reward, 0.0).sum(),
             "flr_no_candidate": no_candidate.sum(), "sampled_n": jnp.asarray(reached.size)}
    return reward, jax.tree.map(lambda x: x.astype(jnp.float32), stats)


def low_samplers(buffer: replay.ReplayState, cfg: DHRLConfig):
    """(sample, sample_g, sample_actor) of the low level: HER batches (future_p 0.8 and 1;
    replay.py ``LowReplay.sample`` / ``sample_g``). The main critics' batch gets
    :func:`low_reward` (sparse or FLR); the distance critics' batch keeps the sparse reward, so
    that the planner's distances stay step counts. The actor's batch is the main one without
    a reward: the actor loss reads none, and the FLR's candidate values are the costliest part
    of a batch."""

    def sample_actor(_: gc_td3.AgentState, key: jax.Array) -> dict:
        return replay.sample(buffer, jax.random.split(key)[0], cfg.low.batch_size,
                             future_p=cfg.low.future_p, future_step=cfg.low.future_step)

    def sample(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = sample_actor(agent, key)
        batch["reward"], batch["metrics"] = low_reward(agent, batch, jax.random.split(key)[1],
                                                       cfg)
        return batch

    def sample_g(_: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = replay.sample(buffer, key, cfg.low.batch_size, future_p=cfg.low.future_p_g,
                              future_step=cfg.low.future_step)
        batch["reward"] = rewards.sparse_reward(batch["next_achieved_goal"], batch["goal"],
                                                delta=cfg.delta)
        return batch

    return sample, sample_g, sample_actor


def high_batch(buffer: replay.ReplayState, dist_fn: planner.DistFn, graph: planner.Graph,
               _: gc_td3.AgentState, key: jax.Array, cfg: DHRLConfig) -> dict:
    """replay.py ``sample_her_transitions_with_subgoaltesting``: every goal relabelled to a
    future achieved goal within ``future_step`` high steps; the subgoal replaced by the
    achieved goal of the next high step except on the test samples (the first
    ``round(subgoal_test_p * B)``), which keep theirs and get ``-penalty`` if it was missed by
    more than ``subgoal_test_threshold``, or ``-gradual_penalty`` if it lies farther than
    ``3 * cutoff`` from every landmark of the current graph."""
    b = cfg.high.batch_size
    batch = replay.sample(buffer, key, b, future_p=1.0, future_step=cfg.high.future_step)
    n_test = round(cfg.subgoal_test_p * b)
    test = jnp.arange(b) < n_test
    reached = batch["next_achieved_goal"]
    action = jnp.where(test[:, None], batch["action"], reached)
    reward = rewards.sparse_reward(reached, batch["goal"], delta=cfg.delta)
    missed = jnp.linalg.norm(action - reached, axis=-1) > cfg.subgoal_test_threshold
    reward = jnp.where(test & missed, -cfg.subgoal_test_penalty, reward)
    lm = graph.landmarks
    # d[n, k]: landmark k -> tested subgoal n, in row blocks: all 300 x 205 pairs in one call
    # need 35 GiB of temporaries at 100 seeds (benchmarks/pairwise_memory.py), 2.8 in blocks.
    d = planner.pairwise_distance(dist_fn, lm.state, batch["action"][:n_test]).T
    far = (planner.graph_to_goal_distance(graph, d) > 3 * cfg.cutoff) & lm.mask.any()
    far = jnp.concatenate([far, jnp.zeros((b - n_test,), bool)])
    reward = jnp.where(test & far, -cfg.gradual_penalty, reward)
    return {**batch, "action": action, "reward": reward}


# --------------------------------------------------------------------------------------------
# Acting
# --------------------------------------------------------------------------------------------


def state_fields(s: State) -> dict:
    return {"obs": s.obs, "achieved_goal": s.info["achieved_goal"], "torso_z": s.info["torso_z"],
            "fallen": s.info["fallen"]}


def act_and_store(low: gc_td3.AgentState, env: Env, env_state: State, goal: jax.Array,
                  t: jax.Array, low_buffer: replay.ReplayState, key: jax.Array,
                  random_phase: jax.Array) -> tuple[State, replay.ReplayState, jax.Array]:
    """One low-level env step of every env towards ``goal`` (uniform random actions during the
    initial rollouts, the exploring policy after), stored at time ``t`` with the episode's
    final goal. Returns the next states, the buffer and the actions."""
    k_act, k_rand = jax.random.split(key)
    n = env_state.obs.shape[0]
    with jax.named_scope("act"):
        action = jnp.where(random_phase,
                           jax.random.uniform(k_rand, (n, env.action_size), minval=-1.0),
                           gc_td3.act(low, env_state.obs, goal, k_act, explore=True))
    with jax.named_scope("physics"):
        nxt = jax.vmap(env.step)(env_state, action)
    with jax.named_scope("replay_insert"):
        low_buffer = replay.insert_step(low_buffer, t, {
            **state_fields(env_state), "action": action, "goal": goal,
            "final_goal": env_state.info["goal"]})
        low_buffer = replay.insert_final(low_buffer, state_fields(nxt))
    return nxt, low_buffer, action


def _new_subgoal(c_high: gc_td3.AgentState, env_state: State, key: jax.Array,
                 random_phase: jax.Array, explore: bool, cfg: DHRLConfig) -> jax.Array:
    """dhrl.py ``get_actions`` at a subgoal boundary: random during the initial rollouts, else
    the high-level actor on (obs, final goal), with noise and clipping when exploring."""
    k_act, k_rand = jax.random.split(key)
    proposed = gc_td3.act(c_high, env_state.obs, env_state.info["goal"], k_act, explore=explore)
    return jnp.where(random_phase, _random_subgoal(k_rand, env_state.obs.shape[0], cfg),
                     proposed)


def train_episode(carry: Carry, episode: jax.Array, env: Env, cfg: DHRLConfig
                  ) -> tuple[Carry, dict]:
    """One round of ``num_envs`` lockstep episodes (dhrl.py ``collect_experience`` with
    training), preceded by a graph rebuild on the rounds that have one. ``episode`` is the
    round index, the same for every seed (not vmapped)."""
    horizon, k = env.config.episode_length, cfg.subgoal_freq
    group, actor_updates = gc_td3.schedule(cfg.updates_per_iter, cfg.low.actor_update_freq)
    h_actor = cfg.high_updates_per_period // cfg.high.actor_update_freq
    random_phase = episode * cfg.num_envs < cfg.initial_episodes
    learning = ~random_phase
    key, k_graph, k_reset = jax.random.split(carry.key, 3)
    rebuild = (episode >= cfg.graph_start_round) & (
        (episode - cfg.graph_start_round) % cfg.graph_every == 0)
    with jax.named_scope("graph_build"):
        graph = jax.lax.cond(rebuild,
                             lambda: graph_from_replay(carry.low, carry.low_buffer, k_graph, cfg),
                             lambda: carry.graph)
    env_state = jax.vmap(env.reset)(jax.random.split(k_reset, cfg.num_envs))

    def env_step(c, t):
        env_state, follower, path, subgoal, low_buffer, low, key = c
        key, k_act, k_upd = jax.random.split(key, 3)
        follower, waypoint = jax.vmap(functools.partial(planner.advance, reach_eps=cfg.reach_eps))(
            follower, path, env_state.info["achieved_goal"], subgoal)
        nxt, low_buffer, _ = act_and_store(low, env, env_state, waypoint, t, low_buffer,
                                           k_act, random_phase)
        sample, sample_g, _ = low_samplers(low_buffer, cfg)
        low, m = gc_td3.learn_if(learning, low, sample, k_upd,
                                 ("critic_loss", "q", "critic_g_loss", *REWARD_STATS),
                                 critic_updates=cfg.updates_per_iter, actor_updates=0,
                                 sample_g=sample_g)
        return (nxt, follower, path, subgoal, low_buffer, low, key), m

    def group_of_steps(c, ts):
        c, m = jax.lax.scan(env_step, c, ts)
        *rest, low_buffer, low, key = c
        key, k_upd = jax.random.split(key)
        _, _, sample_actor = low_samplers(low_buffer, cfg)
        low, m_actor = gc_td3.learn_if(learning, low, sample_actor, k_upd, ("actor_loss",),
                                       critic_updates=0, actor_updates=actor_updates)
        return (*rest, low_buffer, low, key), {**jax.tree.map(jnp.mean, m), **m_actor}

    def period(c, p):
        env_state, low_buffer, high_buffer, low, high, key = c
        key, k_sg, k_high = jax.random.split(key, 3)
        with jax.named_scope("plan"):
            subgoal = _new_subgoal(high, env_state, k_sg, random_phase, True, cfg)
            path = find_paths(low, graph, env_state.obs, subgoal, cfg)
        follower = jax.vmap(lambda _: planner.follower_init())(jnp.arange(cfg.num_envs))
        ts = p * k + jnp.arange(k).reshape(-1, group)
        (nxt, _, _, _, low_buffer, low, key), m = jax.lax.scan(
            group_of_steps, (env_state, follower, path, subgoal, low_buffer, low, key), ts)
        high_buffer = replay.insert_step(high_buffer, p, {
            "obs": env_state.obs, "achieved_goal": env_state.info["achieved_goal"],
            "action": subgoal, "goal": env_state.info["goal"]})
        high_buffer = replay.insert_final(high_buffer, {
            "obs": nxt.obs, "achieved_goal": nxt.info["achieved_goal"]})
        sample_h = functools.partial(high_batch, high_buffer, _dist_fn(low), graph, cfg=cfg)
        with jax.named_scope("high_level"):
            high, m_high = gc_td3.learn_if(learning, high, sample_h, k_high,
                                           ("critic_loss", "q", "actor_loss"),
                                           critic_updates=cfg.high_updates_per_period,
                                           actor_updates=h_actor)
        m = {**jax.tree.map(jnp.mean, m), **{f"high_{n}": v for n, v in m_high.items()},
             "path_length": path.length.mean()}
        return (nxt, low_buffer, high_buffer, low, high, key), m

    (env_state, low_buffer, high_buffer, low, high, key), metrics = jax.lax.scan(
        period, (env_state, carry.low_buffer, carry.high_buffer, carry.low, carry.high, key),
        jnp.arange(horizon // k))
    metrics = jax.tree.map(jnp.mean, metrics)
    metrics.update(reward_gap(metrics))
    metrics["train_success"] = env_state.info["success"].mean()
    metrics["physics_resets"] = env_state.info["physics_resets"].sum().astype(jnp.float32)
    metrics["graph_nodes"] = graph.landmarks.mask.sum().astype(jnp.float32)
    carry = Carry(env_state=env_state, low_buffer=replay.finish_episodes(low_buffer),
                  high_buffer=replay.finish_episodes(high_buffer), low=low, high=high,
                  graph=graph, key=key)
    return carry, metrics


def reward_gap(m: dict) -> dict:
    """Fig. 4b from the episode's :data:`REWARD_STATS` (consumed): mean reward of subgoal-
    reaching transitions from upright and from fallen states, their gap (NaN when a group is
    empty), the fraction of sampled transitions that reach their subgoal (those whose FLR
    reward is computed; NaN before learning starts), and the fraction of reaching transitions
    that are fallen and that had no FLR candidate."""
    up_n, fall_n, sampled_n = m.pop("reach_up_n"), m.pop("reach_fall_n"), m.pop("sampled_n")
    up = m.pop("reach_up_reward") / jnp.where(up_n > 0, up_n, jnp.nan)
    fall = m.pop("reach_fall_reward") / jnp.where(fall_n > 0, fall_n, jnp.nan)
    reach_n = jnp.maximum(up_n + fall_n, 1e-9)
    return {"reach_reward_upright": up, "reach_reward_fallen": fall, "reward_gap": up - fall,
            "reach_frac": (up_n + fall_n) / jnp.where(sampled_n > 0, sampled_n, jnp.nan),
            "reach_fallen_frac": fall_n / reach_n,
            "flr_no_candidate_frac": m.pop("flr_no_candidate") / reach_n}


def evaluate(carry: Carry, key: jax.Array, env: Env, cfg: DHRLConfig) -> dict:
    """Deterministic hierarchy with the planner (dhrl.py ``run_eval``): ``eval_episodes`` from
    the start to ``env.maze.goal`` and as many to goals drawn as in training."""
    n = cfg.eval_episodes
    s0 = evaluation.start_states(env, key, n)
    no = jnp.asarray(False)

    def period(s, _):
        subgoal = _new_subgoal(carry.high, s, key, no, False, cfg)
        path = find_paths(carry.low, carry.graph, s.obs, subgoal, cfg)
        follower = jax.vmap(lambda _: planner.follower_init())(jnp.arange(2 * n))

        def step(c, _):
            s, follower = c
            follower, waypoint = jax.vmap(
                functools.partial(planner.advance, reach_eps=cfg.reach_eps))(
                follower, path, s.info["achieved_goal"], subgoal)
            a = gc_td3.act(carry.low, s.obs, waypoint, key, explore=False)
            return (jax.vmap(env.step)(s, a), follower), None

        (s, _), _ = jax.lax.scan(step, (s, follower), None, length=cfg.subgoal_freq)
        return s, path.length[:n].mean()

    s, path_len = jax.lax.scan(period, s0, None,
                               length=env.config.episode_length // cfg.subgoal_freq)
    return {**evaluation.final_metrics(s.info, n), "eval_path_length": path_len.mean()}
