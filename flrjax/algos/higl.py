"""``--algo higl``: HIGL (Kim et al., NeurIPS 2021), landmark-guided subgoal generation.

A manager (high-level TD3) proposes a subgoal relative to the current position every
``subgoal_freq`` (10) steps; a controller (low-level TD3) chases the absolute target with the
dense reward ``-||phi(s') - g||`` (:func:`rewards.dense_reward`). The manager's actor loss adds
the landmark term: for each sampled state, the landmark on the shortest path to its final
goal is picked from a small graph of *coverage* landmarks (farthest-point samples of the
replay's achieved goals) and *novelty* landmarks (the states the RND predictor knows least);
a pseudo-landmark ``ag + step * (landmark - ag) / ||landmark - ag||`` is then pulled towards
the proposed subgoal in the embedding of an adjacency network trained to put states reachable
within ``adj_k`` steps within distance 1. The planner never acts: it shapes the manager.

Reference: junsu-kim97/HIGL (``higl/higl.py`` Manager/Controller, ``higl/train.py``,
``planner/goal_plan.py``, ``main.py`` and ``scripts/higl_ant_maze_u.sh``); our reading is in
``docs/reference/pig_higl.md``. Deviations, and why:

- the manager and controller are our TD3 (``gc_td3``: MSE critic loss, actor every 2nd
  step) instead of HIGL's (Huber loss, actor every step), and use the run's batch size;
- landmarks are rebuilt once per episode round on the graph schedule, not at every manager
  update; novelty landmarks are the top RND scores among the replay sample just drawn (HIGL
  keeps a priority queue of stale scores); graph distances are the controller's ``-Q``
  through our shortest paths (edges under ``cutoff`` 38 or 1.2x the nearest), not soft value
  iteration;
- the adjacency network learns from replay pairs: positives ``adj_k`` steps apart or less in
  one episode, negatives two random replay states (HIGL/HRAC: a grid of cells visited within
  k steps of each other, accumulated over the run);
- the controller sees the full observation (HIGL zeroes its x, y).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar

import jax
import jax.numpy as jnp
import optax
from brax.envs.base import Env, State
from flax import struct

from flrjax import networks, planner, replay, rewards
from flrjax.agents import gc_td3
from flrjax.algos import hierarchy, hierarchy_flags, onset, rollout
from flrjax.algos.common import Run, reset_envs
from flrjax.algos.registry import Method, register
from flrjax.envs.maze import Maze
from flrjax.metric_names import scoped

ANET = networks.MLP((128, 128, 128), 32)  # higl/models.py ANet: 2 -> 128 x3 -> 32
RND = networks.MLP((128, 128, 128), 128)  # RndPredictor(hidden 128, output_dim 128)


@dataclasses.dataclass(frozen=True)
class HIGLConfig(hierarchy.HierarchyConfig):
    """The shared hierarchy's settings (``low``: the controller; ``high``: the manager,
    relative) and HIGL's own (higl_ant_maze_u.sh / main.py)."""

    n_coverage: int = 20  # --n_landmark_coverage
    n_novelty: int = 20  # --n_landmark_novelty
    landmark_sample: int = 1000  # --initial_sample
    landmark_weight: float = 20.0  # --landmark_loss_coeff
    landmark_step: float = 2.0  # --delta: pseudo-landmark step towards the landmark
    goal_thr: float = 10.0  # -goal_thr: a goal this close is itself the landmark
    adj_k: int = 5  # int(manager_propose_freq * adj_factor) = int(10 * 0.5)
    adj_margin: float = 1.1  # (r_margin_pos + r_margin_neg) / 2
    high_reward_scale: float = 0.1  # --man_rew_scale
    aux_updates: int = 25  # adjacency-network and RND steps per episode round
    aux_batch: int = 128  # --r_batch_size 64 / --rnd_batch_size 128
    correction_candidates: int = 10  # --candidate_goals: HIRO's off-policy correction


@dataclasses.dataclass(frozen=True)
class HIGLOptions(hierarchy_flags.HighOptions, hierarchy_flags.GraphOptions):
    """HIGL's flags: the manager's learning rates and the graph's, with HIGL's own defaults
    for the subgoal period, the cutoff and the manager's noise (see :func:`from_run`)."""

    SUBGOAL_NOISE_EPS: ClassVar[float] = 1.0
    GRAPH_DEFAULTS: ClassVar[dict[str, dict]] = {
        "ant": dict(subgoal_freq=10, cutoff=38.0), "point": dict(subgoal_freq=5, cutoff=38.0)}


def from_run(run: Run, env: Env) -> HIGLConfig:
    """HIGL (higl_ant_maze_u.sh / main.py): subgoals relative to the position every 10 steps
    (5 on the point mass) within the maze's half extent, manager noise 1 and target noise 0.2,
    controller discount 0.95 with the dense reward, plain Q critics (no distance
    parametrisation), no HER, graph edges under 38 (``--clip_v``); the run's
    ``--subgoal-freq`` and ``--cutoff`` where given (:attr:`HIGLOptions.GRAPH_DEFAULTS`)."""
    base = hierarchy.from_run(run, env, HIGLConfig, high_hp=hierarchy_flags.high_numbers(run))
    lo, hi = env.maze.bounds
    scale = tuple(float(h - lo_) / 2 for lo_, h in zip(lo, hi, strict=True))
    low = dataclasses.replace(base.low, dist_critic=False, clip_return=1e6)
    high = dataclasses.replace(base.high, action_max=scale, action_offset=(0.0, 0.0),
                               dist_critic=False, clip_return=1e6)
    low_hp = base.low_hp.updated(gamma=0.95 if run.gamma is None else run.gamma,
                                 future_p=0.0)
    high_hp = base.high_hp.updated(target_noise=0.2, future_p=0.0)
    return dataclasses.replace(base, low=low, high=high, low_hp=low_hp, high_hp=high_hp)


def validate(run: Run, points: list[dict], env: Env) -> None:
    """The graph's flags (HIGL's defaults in place of the unset ones)."""
    hierarchy_flags.validate(run)


def resolved(cfg: HIGLConfig) -> dict:
    """The updates' matrix operands (their default follows the device)."""
    return {"train_precision": cfg.low.train_precision}


def hparams(cfg: HIGLConfig) -> dict[str, gc_td3.Hparams]:
    """Both levels' traced numbers, as :func:`init` puts them in the agents' states."""
    return hierarchy.hparams(cfg)


@struct.dataclass
class AuxState:
    """The adjacency network and the RND novelty estimator, with their optimisers."""

    anet: networks.Params
    anet_opt: optax.OptState
    rnd: networks.Params
    rnd_opt: optax.OptState
    rnd_target: networks.Params


@struct.dataclass
class Carry:
    env_state: State
    low_buffer: replay.ReplayState
    high_buffer: replay.ReplayState
    low: gc_td3.AgentState
    high: gc_td3.AgentState
    aux: AuxState
    graph: planner.Graph
    key: jax.Array


_ANET_TX = optax.adam(2e-4)  # --lr_r
_RND_TX = optax.adam(1e-3)  # --rnd_lr


def _high_spec(env: Env, cfg: HIGLConfig) -> tuple[dict, dict]:
    """Manager transitions keep their reward and the period's low-level observations and
    actions for the off-policy correction."""
    c = cfg.subgoal_freq
    return hierarchy.high_spec(
        env, reward=jax.ShapeDtypeStruct((), jnp.float32),
        low_obs=jax.ShapeDtypeStruct((c, env.observation_size), jnp.float32),
        low_action=jax.ShapeDtypeStruct((c, env.action_size), jnp.float32))


def init(key: jax.Array, env: Env, cfg: HIGLConfig, hp: dict | None = None) -> Carry:
    """A fresh seed: both agents (with ``hp``, default :func:`hparams`), the auxiliary
    networks, empty buffers, no landmarks, ``num_envs`` envs reset."""
    k_low, k_high, k_a, k_r, k_t, k_env, k_carry = jax.random.split(key, 7)
    obs = env.observation_size
    hp = hparams(cfg) if hp is None else hp
    low = gc_td3.init(k_low, obs, 2, env.action_size, cfg.low, hp["low"])
    high = gc_td3.init(k_high, obs, 2, 2, cfg.high, hp["high"])
    anet = networks.init_params(ANET, k_a, jnp.zeros((1, 2)))
    rnd = networks.init_params(RND, k_r, jnp.zeros((1, obs)))
    aux = AuxState(anet=anet, anet_opt=_ANET_TX.init(anet), rnd=rnd, rnd_opt=_RND_TX.init(rnd),
                   rnd_target=networks.init_params(RND, k_t, jnp.zeros((1, obs))))
    horizon = env.config.episode_length
    low_buffer = replay.init(cfg.buffer_episodes, horizon, cfg.num_envs, *hierarchy.low_spec(env))
    high_buffer = replay.init(cfg.buffer_episodes, horizon // cfg.subgoal_freq, cfg.num_envs,
                              *_high_spec(env, cfg))
    env_state = reset_envs(env, k_env, cfg.num_envs)
    n = cfg.n_coverage + cfg.n_novelty
    return Carry(env_state=env_state, low_buffer=low_buffer, high_buffer=high_buffer, low=low,
                 high=high, aux=aux, graph=planner.empty_graph(n, obs, 2), key=k_carry)


# --------------------------------------------------------------------------------------------
# Landmarks: coverage, novelty, graph, selection
# --------------------------------------------------------------------------------------------


def value_distance(low: gc_td3.AgentState, obs: jax.Array, goal: jax.Array) -> jax.Array:
    """The controller's ``-Q(s, g, pi(s, g))`` (twin min), at least 0: goal_plan.py's edge
    weight, a discounted sum of distances still to cover."""
    return jnp.maximum(-gc_td3.q_value(low, obs, goal), 0.0)


def novelty(aux: AuxState, obs: jax.Array) -> jax.Array:
    """RND novelty ``0.5 * ||f(s) - f_target(s)||^2`` (higl.py ``RandomNetworkDistillation``)."""
    return 0.5 * jnp.sum(jnp.square(RND.apply(aux.rnd, obs) - RND.apply(aux.rnd_target, obs)),
                         axis=-1)


def build_landmarks(low: gc_td3.AgentState, aux: AuxState, buffer: replay.ReplayState,
                    key: jax.Array, cfg: HIGLConfig, maze: Maze
                    ) -> tuple[planner.Graph, dict]:
    """``n_coverage`` FPS landmarks (Euclidean, on achieved goals) and the ``n_novelty`` most
    novel states of ``landmark_sample`` replay states, joined by the controller's distances;
    with the graph's :func:`onset.build_stats` in ``maze``."""
    data = replay.sample(buffer, key, cfg.landmark_sample, future_p=0.0)
    obs, ag = data["obs"], data["achieved_goal"]
    eucl = jnp.linalg.norm(ag[:, None] - ag[None], axis=-1)
    cover = planner.farthest_point_sampling(0, eucl, obs, ag, max_nodes=cfg.n_coverage,
                                            stop_eps=0.0, min_nodes=cfg.n_coverage)
    _, top = jax.lax.top_k(novelty(aux, obs), cfg.n_novelty)
    lm = planner.Landmarks(
        index=jnp.concatenate([cover.index, top.astype(jnp.int32)]),
        state=jnp.concatenate([cover.state, obs[top]]),
        goal=jnp.concatenate([cover.goal, ag[top]]),
        mask=jnp.concatenate([cover.mask, jnp.ones((cfg.n_novelty,), bool)]))
    pdist = planner.pairwise_distance(lambda o, g: value_distance(low, o, g), lm.state, lm.goal)
    graph = planner.graph_from_distances(lm, pdist, cutoff=cfg.cutoff)
    return graph, onset.build_stats(graph, pdist, maze, ag, buffer)


def pseudo_landmarks(dist_fn: planner.DistFn, graph: planner.Graph, obs: jax.Array,
                     ag: jax.Array, goal: jax.Array, cfg: HIGLConfig) -> jax.Array:
    """For each row: the landmark on the shortest path towards its goal (goal_plan.py
    ``Planner.__call__``: min over landmarks j of d(s, j) + d(j -> ... -> goal); the goal
    itself when it is within ``goal_thr``), then the point ``landmark_step`` from the achieved
    goal towards it (higl.py ``actor_loss``). Without a usable landmark, the achieved goal.
    ``dist_fn`` is the controller's :func:`value_distance` in training."""
    lm, cutoff = graph.landmarks, cfg.cutoff
    b, k = obs.shape[0], lm.goal.shape[0]

    def dist(o, g):  # rows x landmarks, flattened into one batched call
        return dist_fn(o.reshape(b * k, -1), g.reshape(b * k, -1)).reshape(b, k)

    d_s = dist(jnp.repeat(obs[:, None], k, 1), jnp.broadcast_to(lm.goal, (b, k, 2)))
    d_s = jnp.where(lm.mask & (d_s < cutoff), d_s, jnp.inf)
    d_g = dist(jnp.broadcast_to(lm.state, (b, *lm.state.shape)), jnp.repeat(goal[:, None], k, 1))
    d_g = jnp.where(lm.mask & (d_g < cutoff), d_g, jnp.inf)
    to_goal = jnp.min(graph.dist[None] + d_g[:, None, :], axis=-1)  # [B, K]
    total = d_s + to_goal
    best = jnp.argmin(total, axis=-1)
    found = jnp.isfinite(jnp.min(total, axis=-1))
    near = dist_fn(obs, goal) < cfg.goal_thr
    target = jnp.where(near[:, None], goal, jnp.where(found[:, None], lm.goal[best], ag))
    step = target - ag
    norm = jnp.linalg.norm(step, axis=-1, keepdims=True)
    return ag + jnp.where(norm > 0, cfg.landmark_step * step / jnp.maximum(norm, 1e-6), 0.0)


def landmark_loss(anet: networks.Params, cfg: HIGLConfig) -> gc_td3.ActorExtra:
    """The manager's extra actor loss: ``weight * mean relu(||A(pl) - A(ag + sg)|| - margin)``
    with the adjacency network A fixed, the proposed relative subgoal ``sg = pi``."""

    def extra(_state, _actor_params, pi: jax.Array, batch) -> tuple[jax.Array, dict]:
        e_pl = jax.lax.stop_gradient(ANET.apply(anet, batch["pseudo_landmark"]))
        e_sg = ANET.apply(anet, batch["achieved_goal"] + pi)
        gap = jnp.linalg.norm(e_pl - e_sg + 1e-9, axis=-1)
        return cfg.landmark_weight * jnp.mean(jax.nn.relu(gap - cfg.adj_margin)), {}

    return extra


# --------------------------------------------------------------------------------------------
# Auxiliary networks
# --------------------------------------------------------------------------------------------


def adjacency_loss(anet: networks.Params, near: tuple, far: tuple) -> jax.Array:
    """HRAC's contrastive loss: pairs ``near`` (label 1) within distance 1.0 of each other in
    the embedding, pairs ``far`` (label 0) beyond 1.2."""
    def dist(a: jax.Array, b: jax.Array) -> jax.Array:
        return jnp.linalg.norm(ANET.apply(anet, a) - ANET.apply(anet, b) + 1e-9, axis=-1)

    d_near, d_far = dist(*near), dist(*far)
    return jnp.mean(jax.nn.relu(d_near - 1.0)) + jnp.mean(jax.nn.relu(1.2 - d_far))


def train_aux(aux: AuxState, buffer: replay.ReplayState, key: jax.Array, cfg: HIGLConfig
              ) -> tuple[AuxState, dict]:
    """``aux_updates`` steps of the adjacency network (pairs ``<= adj_k`` steps apart in one
    episode vs random pairs) and of the RND predictor (on replay states)."""

    def one(a: AuxState, k: jax.Array):
        k_near, k_far1, k_far2 = jax.random.split(k, 3)
        near = replay.sample(buffer, k_near, cfg.aux_batch, future_p=1.0,
                             future_step=cfg.adj_k)
        far1 = replay.sample(buffer, k_far1, cfg.aux_batch, future_p=0.0)
        far2 = replay.sample(buffer, k_far2, cfg.aux_batch, future_p=0.0)
        l_adj, g = jax.value_and_grad(adjacency_loss)(
            a.anet, (near["achieved_goal"], near["future_achieved_goal"]),
            (far1["achieved_goal"], far2["achieved_goal"]))
        upd, anet_opt = _ANET_TX.update(g, a.anet_opt, a.anet)
        anet = optax.apply_updates(a.anet, upd)
        l_rnd, g = jax.value_and_grad(lambda p: jnp.mean(
            novelty(a.replace(rnd=p), far1["obs"])))(a.rnd)
        upd, rnd_opt = _RND_TX.update(g, a.rnd_opt, a.rnd)
        rnd = optax.apply_updates(a.rnd, upd)
        return a.replace(anet=anet, anet_opt=anet_opt, rnd=rnd, rnd_opt=rnd_opt), (l_adj, l_rnd)

    aux, (l_adj, l_rnd) = jax.lax.scan(one, aux, jax.random.split(key, cfg.aux_updates))
    return aux, {"adjacency_loss": l_adj.mean(), "rnd_loss": l_rnd.mean()}


# --------------------------------------------------------------------------------------------
# Training
# --------------------------------------------------------------------------------------------


def _low_sampler(buffer: replay.ReplayState, cfg: HIGLConfig):
    """Controller batches: no HER (HIGL's controller has none), dense reward to the stored
    absolute subgoal (utils.py ``get_reward_function``, ``ctrl_rew_scale`` 1)."""

    def sample(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = replay.sample(buffer, key, cfg.low.batch_size, future_p=agent.hp.future_p)
        batch["reward"] = rewards.dense_reward(batch["next_achieved_goal"], batch["goal"])
        return batch

    return sample


def corrected_subgoals(low: gc_td3.AgentState, batch: dict, key: jax.Array, cfg: HIGLConfig
                       ) -> jax.Array:
    """HIRO's off-policy correction (higl.py ``Manager.off_policy_corrections``): of the stored
    subgoal, the achieved displacement and ``correction_candidates`` Gaussian draws around it
    (std half the subgoal range, clipped to it), the one under which the *current* controller
    best explains the period's stored actions: max of ``-1/2 sum_t ||pi(s_t, ag_0 + sg) -
    a_t||^2``. Ties keep the stored subgoal."""
    scale = jnp.asarray(cfg.high.action_max)
    ag0 = batch["achieved_goal"]
    diff = batch["next_achieved_goal"] - ag0
    b, n = ag0.shape[0], cfg.correction_candidates
    noise = diff[:, None] + 0.5 * scale * jax.random.normal(key, (b, n, 2))
    cands = jnp.clip(jnp.concatenate([batch["action"][:, None], diff[:, None], noise], 1),
                     -scale, scale)  # [B, n + 2, 2]
    obs, act = batch["low_obs"], batch["low_action"]  # [B, c, o], [B, c, A]
    m, c = cands.shape[1], obs.shape[1]
    goals = jnp.broadcast_to((ag0[:, None] + cands)[:, :, None], (b, m, c, 2))
    obs = jnp.broadcast_to(obs[:, None], (b, m, *obs.shape[1:]))
    pi = gc_td3.policy(low, low.actor.params, obs, goals)
    score = -0.5 * jnp.sum(jnp.square(pi - act[:, None]), axis=(-1, -2))
    return cands[jnp.arange(b), jnp.argmax(score, axis=1)]


def _high_sampler(buffer: replay.ReplayState, low: gc_td3.AgentState, graph: planner.Graph,
                  cfg: HIGLConfig):
    """Manager batches with their stored rewards, off-policy-corrected subgoals and
    pseudo-landmarks (no HER)."""

    def sample(high: gc_td3.AgentState, key: jax.Array) -> dict:
        k_s, k_c = jax.random.split(key)
        batch = replay.sample(buffer, k_s, cfg.high.batch_size, future_p=high.hp.future_p)
        batch["action"] = corrected_subgoals(low, batch, k_c, cfg)
        batch["pseudo_landmark"] = pseudo_landmarks(
            functools.partial(value_distance, low), graph, batch["obs"],
            batch["achieved_goal"], batch["goal"], cfg)
        return batch

    return sample


def train_episode(carry: Carry, episode: jax.Array, env: Env, cfg: HIGLConfig
                  ) -> tuple[Carry, dict]:
    """One round of ``num_envs`` lockstep episodes (higl/train.py), after the landmark
    rebuild and the adjacency/RND training on the rounds that have them."""
    horizon, k = env.config.episode_length, cfg.subgoal_freq
    rnd = hierarchy.start_round(episode, cfg)
    key, k_graph, k_aux, k_reset = jax.random.split(carry.key, 4)
    aux, m_aux = jax.lax.cond(
        rnd.learning, lambda: train_aux(carry.aux, carry.low_buffer, k_aux, cfg),
        lambda: (carry.aux, {"adjacency_loss": jnp.float32(0), "rnd_loss": jnp.float32(0)}))
    graph, graph_m = hierarchy.refresh_graph(episode, cfg, lambda: build_landmarks(
        carry.low, aux, carry.low_buffer, k_graph, cfg, env.maze), carry.graph)
    env_state = reset_envs(env, k_reset, cfg.num_envs)

    def env_step(c, t):
        env_state, subgoal, ret, low_buffer, low, key = c
        key, k_act, k_upd = jax.random.split(key, 3)
        nxt, low_buffer, action = hierarchy.act_and_store(low, env, env_state, subgoal, t,
                                                          low_buffer, jax.random.split(k_act),
                                                          rnd.random_phase)
        ret = ret - cfg.high_reward_scale * (~nxt.info["success"]).astype(jnp.float32)
        low, m = gc_td3.learn_if(rnd.learning, low, _low_sampler(low_buffer, cfg), k_upd,
                                 ("critic_loss", "q"), critic_updates=cfg.updates_per_iter,
                                 actor_updates=0)
        return (nxt, subgoal, ret, low_buffer, low, key), (scoped("low", m),
                                                           (env_state.obs, action))

    def choose(c, p):
        env_state, low_buffer, _, low, high, key = c
        key, k_sg, k_rand, k_high = jax.random.split(key, 4)
        ag = env_state.info["achieved_goal"]
        scale = jnp.asarray(cfg.high.action_max)
        delta = jnp.where(
            rnd.random_phase, scale * jax.random.uniform(k_rand, (cfg.num_envs, 2), minval=-1.0),
            gc_td3.act(high, env_state.obs, env_state.info["goal"], k_sg, explore=True))
        ret0 = jnp.zeros((cfg.num_envs,))
        return (env_state, ag + delta, ret0, low_buffer, low, key), (delta, k_high)

    def finish(c, low_c, context, p, m, out):
        env_state, _, high_buffer, _, high, _ = c
        nxt, _, ret, low_buffer, low, key = low_c
        delta, k_high = context
        low_obs, low_action = out

        def per_env(x):  # [groups, group, E, ...] -> [E, k, ...]
            return jnp.moveaxis(x.reshape(k, *x.shape[2:]), 0, 1)

        high_buffer = hierarchy.store_high(high_buffer, p, env_state, nxt, delta, reward=ret,
                                           low_obs=per_env(low_obs),
                                           low_action=per_env(low_action))
        high, m_high = hierarchy.learn_high(
            rnd.learning, high, _high_sampler(high_buffer, low, graph, cfg), k_high, cfg,
            ("critic_loss", "q", "actor_loss", "actor_extra"),
            actor_extra=landmark_loss(aux.anet, cfg))
        subgoal = env_state.info["achieved_goal"] + delta
        m = {**jax.tree.map(jnp.mean, m), **m_high,
             **scoped("stats", onset.subgoal_stats(env.maze, env_state, nxt, subgoal))}
        return (nxt, low_buffer, high_buffer, low, high, key), m

    (env_state, low_buffer, high_buffer, low, high, key), metrics = rollout.train(
        env_step, hierarchy.actor_catch_up(rnd, lambda buffer: _low_sampler(buffer, cfg)),
        (env_state, carry.low_buffer, carry.high_buffer, carry.low, carry.high, key), horizon,
        rnd.group, rollout.High(k, choose, finish))
    metrics = hierarchy.round_metrics(metrics, env_state, graph)
    metrics["high/landmark_loss"] = metrics.pop("high/actor_extra")
    metrics.update(scoped("aux", m_aux))
    metrics.update(scoped("stats", graph_m))
    carry = Carry(env_state=env_state, low_buffer=replay.finish_episodes(low_buffer),
                  high_buffer=replay.finish_episodes(high_buffer), low=low, high=high, aux=aux,
                  graph=graph, key=key)
    return carry, metrics


def evaluate(carry: Carry, key: jax.Array, env: Env, cfg: HIGLConfig, trace: bool = False):
    """Deterministic manager and controller (higl/train.py ``evaluate_policy``; the planner does
    not act), by :func:`hierarchy.evaluate`: ``eval_episodes`` to ``env.maze.goal`` and as many
    to goals drawn as in training; the manager's subgoal, relative to the position at each
    period's start, is the controller's target for the period. ``trace``: also every step's
    record (:func:`rollout.traced`)."""

    def plan(s):
        sg = s.info["achieved_goal"] + gc_td3.act(carry.high, s.obs, s.info["goal"], key,
                                                  explore=False)
        return hierarchy.low_policy(carry.low, key, sg), None, None, None

    n = cfg.eval_episodes
    s, _, rec = hierarchy.evaluate(carry.low, key, env, n, trace, plan, cfg.subgoal_freq)
    return rollout.report(s, n, rec, trace)


def params(carry: Carry) -> tuple:
    """The manager's, the controller's and the auxiliary networks' trained parameters."""
    return (gc_td3.trained(carry.low), gc_td3.trained(carry.high), carry.aux.anet,
            carry.aux.rnd)


register(Method("higl", "HIGL", HIGLOptions, from_run, hparams, init, train_episode, evaluate,
                params, validate=validate, resolved=resolved))
