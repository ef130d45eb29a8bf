"""``--algo pig`` / ``flr_pig``: PIG (Kim et al., ICLR 2023), planning-guided self-imitation.

One goal-conditioned policy pi(s, g), trained on final goals with HER, and DHRL's landmark
graph (both from :mod:`flrjax.algos.hierarchy`): at every step, with probability ``plan_eps``,
the agent plans a path to its final goal and acts towards a waypoint of it: the first, or one
further along by PIG's subgoal skipping (:func:`skip_target`: each hop taken with probability
``jump_temp / ref_loss``, ``ref_loss`` being the last round's imitation loss, so the better
pi(s, g) imitates its plans the further ahead it aims). The waypoints it planned are stored
with the transition, and the actor loss adds the imitation of pi at those waypoints
(:func:`imitation_loss`, a term of the actor loss): pi(s, g) learns to do what pi does
towards the nearer subgoals. ``flr_pig`` replaces the sparse reward of the critic's HER batches
by the forward-looking reward, as ``flr_dhrl`` does for DHRL's low level. Evaluation follows
the planner, with skipping, at every step, as PIG's test agent does (``success_rate``), and
also reports pi(s, g) alone (``no_plan_*``, the reference's ``_eval_test_agent_no_plan``).

Reference: junsu-kim97/PIG (``algos/ddpg_agent.py``, ``planner/goal_plan.py``,
``scripts/train_antmaze.sh``); our reading is in ``docs/reference/pig_higl.md``. Deviations,
to keep one learner and one planner across the methods we compare, and why:

- TD3 of DHRL's low level (``gc_td3``) instead of PIG's DDPG, and DHRL's planner (FPS
  landmarks, distance critics, shortest paths; graph rebuilt on DHRL's schedule) instead of
  PIG's soft value iteration with sampled paths (so the path is the shortest one, not a sample;
  skipping is then the only randomness in which waypoint the agent heads for);
- the imitation term has a gradient (the released code computes it under ``no_grad``) and is
  applied to samples whose goal was not relabelled (the stored plan was made for that goal;
  the released code also uses it for relabelled goals); ``ref_loss``, the mean of this term,
  therefore averages over other samples than the released code's;
- PIG's warm-up (no planning before 500 episodes) is the graph's start, ``graph_start_round``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State
from flax import struct

from flrjax import planner, replay
from flrjax.agents import gc_td3
from flrjax.algos import flr, hierarchy, hierarchy_flags, low_batches, rollout
from flrjax.algos.common import HEROptions, Run, reset_envs
from flrjax.algos.registry import Method, register
from flrjax.metric_names import scoped
from flrjax.options import Sweepable, flag


@dataclasses.dataclass(frozen=True)
class PIGConfig(hierarchy.HierarchyConfig):
    """The shared hierarchy's settings (``low``: the policy; ``high``: only its box) and PIG's
    own."""

    plan_eps: float = 0.5  # train_antmaze.sh --plan_eps: chance per step of acting by the plan
    path_len: int = 10  # --plan_budget: waypoints stored for the imitation
    # --jump_temp 10 (train_antmaze.sh), divided by 30**2: the reference compares it with an
    # imitation loss of torques in +-30 (ddpg_agent.py goal_loss), ours is of actions in [-1, 1]
    jump_temp: float = 10.0 / 30.0**2
    # --lambda_goal_loss 0.001 (train_antmaze.sh) on torques of +-30 (ddpg_agent.py goal_loss),
    # i.e. 0.001 * 30**2 on our actions in [-1, 1]
    imitation_weight: float = 0.001 * 30.0**2


#: PIG's settings that flags change (:class:`PIGConfig` has the reference's values and sources).
PIG_DEFAULTS = dict(pig_jump_temp=PIGConfig.jump_temp)
#: The low level's value readings PIG takes (k_step needs a high level's subgoal period).
LOW_VALUES = ("infinite", "reach_ends")


@dataclasses.dataclass(frozen=True)
class PIGOptions(HEROptions, hierarchy_flags.GraphOptions, hierarchy_flags.LowValueOptions):
    """PIG's flags: the policy's HER and value reading, the graph, and subgoal skipping."""

    pig_jump_temp: float | tuple[float, ...] | None = flag(
        None, "subgoal skipping, each hop with probability jump_temp / imitation loss (default "
              "10/30**2, the reference's 10 on torques of +-30; 0: off); comma-separated "
              "values sweep it", "PIG", sweep=Sweepable("jump_temp", PIG_DEFAULTS["pig_jump_temp"]),
        check=(lambda v: v >= 0, ">= 0"))


@dataclasses.dataclass(frozen=True)
class FLRPIGOptions(PIGOptions, flr.FLROptions, hierarchy_flags.KernelOptions):
    """FLR+PIG's flags: PIG's, the forward-looking reward's and its values' kernel."""


def from_run(run: Run, env: Env) -> PIGConfig:
    """The run's flags as PIG's config: the shared hierarchy's and the subgoal skipping's
    ``jump_temp``."""
    jump_temp = PIG_DEFAULTS["pig_jump_temp"] if run.pig_jump_temp is None else run.pig_jump_temp
    return hierarchy.from_run(run, env, PIGConfig, low_value=run.low_value, n_step=run.n_step,
                              critic_atoms=run.critic_atoms,
                              jump_temp=jump_temp)


def from_run_flr(run: Run, env: Env) -> PIGConfig:
    """FLR+PIG's config: PIG's with the forward-looking reward."""
    return dataclasses.replace(from_run(run, env), flr=flr.from_run(run))


def validate(run: Run, points: list[dict], env: Env) -> None:
    """The graph's flags and the low level's value reading."""
    hierarchy_flags.validate(run)
    hierarchy_flags.validate_low_value(
        run, LOW_VALUES, "k_step counts the steps left of a high level's subgoal period; PIG "
                         "has no high level")


def validate_flr(run: Run, points: list[dict], env: Env) -> None:
    """PIG's checks, FLR's settings, and the fused kernel's operands for eq. 5."""
    validate(run, points, env)
    flr.validate(run, points, env)
    hierarchy_flags.validate_kernel(run, {"flr_precision": hierarchy_flags.gpu_default(
        run.flr_precision, flr.FLR_GPU_DEFAULTS["flr_precision"])})


def resolved(cfg: PIGConfig) -> dict:
    """The updates' and eq. 5's settings whose defaults follow the device."""
    return {"train_precision": cfg.low.train_precision,
            **(flr.resolved(cfg.flr) if cfg.flr is not None else {})}


@struct.dataclass
class Carry:
    env_state: State  # [num_envs]
    buffer: replay.ReplayState
    agent: gc_td3.AgentState
    graph: planner.Graph
    ref_loss: jax.Array  # last round's mean imitation loss (0 before any: no skipping)
    key: jax.Array


def _spec(env: Env, cfg: PIGConfig) -> tuple[dict, dict]:
    states, transitions = hierarchy.low_spec(env)
    transitions["imitation_goal"] = jax.ShapeDtypeStruct((cfg.path_len, 2), jnp.float32)
    transitions["imitation_mask"] = jax.ShapeDtypeStruct((cfg.path_len,), jnp.bool_)
    return states, transitions


def hparams(cfg: PIGConfig) -> gc_td3.Hparams:
    """The policy's traced numbers (the low level's; the high level has no agent)."""
    return cfg.low_hp


def init(key: jax.Array, env: Env, cfg: PIGConfig, hp: gc_td3.Hparams | None = None
         ) -> Carry:
    """A fresh seed: the agent (with ``hp``, default :func:`hparams`), an empty buffer, no
    graph, ``num_envs`` envs reset."""
    k_agent, k_env, k_carry = jax.random.split(key, 3)
    agent = gc_td3.init(k_agent, env.observation_size, 2, env.action_size, cfg.low,
                        hparams(cfg) if hp is None else hp)
    buffer = replay.init(cfg.buffer_episodes, env.config.episode_length, cfg.num_envs,
                         *_spec(env, cfg))
    env_state = reset_envs(env, k_env, cfg.num_envs)
    return Carry(env_state=env_state, buffer=buffer, agent=agent,
                 graph=planner.empty_graph(cfg.max_nodes, env.observation_size, 2),
                 ref_loss=jnp.zeros((), jnp.float32), key=k_carry)


def skip_prob(ref_loss: jax.Array, cfg: PIGConfig) -> jax.Array:
    """Planner.__call__ ``jump``: the chance of each hop past a waypoint, ``clip(jump_temp /
    ref_loss, 0, 1)``, and 0 while there is no imitation loss yet."""
    return jnp.where(ref_loss > 0, jnp.clip(cfg.jump_temp / jnp.maximum(ref_loss, 1e-12), 0, 1),
                     0.0)


def skip_target(key: jax.Array, waypoints: jax.Array, length: jax.Array, goal: jax.Array,
                p: jax.Array) -> jax.Array:
    """PIG's subgoal skipping (Planner.__call__): along ``[w_0, .., w_{n-1}, goal]`` (``n =
    length``), hop forward while a Bernoulli(``p``) draw succeeds; the element reached
    ([E, 2]). ``waypoints[E, L, 2]``, ``length[E]``, ``goal[E, 2]``."""
    hops = jnp.sum(jnp.cumprod(jax.random.uniform(key, waypoints.shape[:2]) < p, axis=1), axis=1)
    k = jnp.minimum(hops, length)
    chosen = jnp.take_along_axis(waypoints, jnp.minimum(k, waypoints.shape[1] - 1)[:, None, None],
                                 axis=1)[:, 0]
    return jnp.where((k < length)[:, None], chosen, goal)


def _plan_step(agent: gc_td3.AgentState, graph: planner.Graph, s: State, ref_loss: jax.Array,
               key: jax.Array, cfg: PIGConfig) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(the waypoint to head for [E, 2], the plan's waypoints [E, L, 2], their mask [E, L]) of a
    fresh plan from every env's state to its final goal (``Planner.__call__`` every step): the
    first waypoint, or the goal if the path is empty, or one further along by skipping."""
    goal = s.info["goal"]
    path = hierarchy.find_paths(agent, graph, s.obs, goal, dataclasses.replace(
        cfg, max_path_len=cfg.path_len))
    mask = jnp.arange(cfg.path_len)[None] < path.length[:, None]
    target = skip_target(key, path.waypoint, path.length, goal, skip_prob(ref_loss, cfg))
    return target, path.waypoint, mask


def imitation_loss(weight: float) -> gc_td3.ActorExtra:
    """PIG's subgoal imitation (ddpg_agent.py ``_update_network``), a term of the actor loss:
    ``weight * masked mean of (pi(s, g) - stop_gradient(pi(s, sg_l)))**2`` over the planned
    subgoals ``sg_l`` (``imitation_goal[B, L, g]`` where ``imitation_mask[B, L]``) and the
    action dimensions, so the goal-conditioned policy copies what it does towards the nearer
    subgoals of its plan. Its metric ``imitation`` is the unweighted mean. (PIG's released code
    computes this term under ``torch.no_grad()``, so it never reaches the gradient; we follow
    the paper.)"""

    def extra(agent: gc_td3.AgentState, actor_params, pi: jax.Array, batch
              ) -> tuple[jax.Array, dict]:
        sg, mask = batch["imitation_goal"], batch["imitation_mask"]
        obs = jnp.broadcast_to(batch["obs"][:, None], sg.shape[:2] + batch["obs"].shape[1:])
        teacher = jax.lax.stop_gradient(gc_td3.policy(agent, actor_params, obs, sg))
        cfg = agent.config
        err = jnp.square(gc_td3.unit_action(pi, cfg)[:, None] - gc_td3.unit_action(teacher, cfg))
        n = jnp.maximum(jnp.sum(mask) * err.shape[-1], 1.0)
        imitation = jnp.sum(jnp.where(mask[..., None], err, 0.0)) / n
        return weight * imitation, {"imitation": imitation}

    return extra


def _samplers(buffer: replay.ReplayState, cfg: PIGConfig):
    """The low level's (sample, sample_g, sample_actor) (:func:`low_batches.low_samplers`: sparse
    or FLR reward, distance critics sparse), with the imitation targets kept only where the
    goal is the one the stored plan was made for (not HER-relabelled)."""

    def keep_own_plans(sampler):
        def sample(agent: gc_td3.AgentState, key: jax.Array) -> dict:
            batch = sampler(agent, key)
            batch["imitation_mask"] = batch["imitation_mask"] & ~batch["relabelled"][:, None]
            return batch
        return sample

    sample, sample_g, sample_actor = low_batches.low_samplers(buffer, cfg)
    return keep_own_plans(sample), sample_g, keep_own_plans(sample_actor)


def train_episode(carry: Carry, episode: jax.Array, env: Env, cfg: PIGConfig
                  ) -> tuple[Carry, dict]:
    """One round of ``num_envs`` lockstep episodes, after a graph rebuild on the rounds that
    have one (:mod:`flrjax.algos.hierarchy`). ``episode`` is the unbatched round index."""
    rnd = hierarchy.start_round(episode, cfg)
    key, k_graph, k_reset = jax.random.split(carry.key, 3)
    graph, graph_m = hierarchy.refresh_graph(episode, cfg, lambda: hierarchy.graph_from_replay(
        carry.agent, carry.buffer, k_graph, cfg, env.maze), carry.graph)
    env_state = reset_envs(env, k_reset, cfg.num_envs)

    def env_step(c, t):
        env_state, buffer, agent, key = c
        key, k_act, k_rand, k_plan, k_skip, k_upd = jax.random.split(key, 6)
        target, waypoints, mask = _plan_step(agent, graph, env_state, carry.ref_loss, k_skip, cfg)
        use_plan = jax.random.bernoulli(k_plan, cfg.plan_eps, (cfg.num_envs,))
        goal = env_state.info["goal"]
        planned = gc_td3.act(agent, env_state.obs, target, k_act, explore=False)
        explored = gc_td3.act(agent, env_state.obs, goal, k_act, explore=True)
        action = jnp.where(use_plan[:, None], planned, explored)
        action = jnp.where(
            rnd.random_phase,
            jax.random.uniform(k_rand, (cfg.num_envs, env.action_size), minval=-1.0), action)
        nxt = jax.vmap(env.step)(env_state, action)
        buffer = replay.insert_step(buffer, t, {
            **hierarchy.state_fields(env_state), "action": action, "goal": goal,
            "final_goal": goal, "imitation_goal": waypoints,
            "imitation_mask": mask & use_plan[:, None]})
        buffer = replay.insert_final(buffer, hierarchy.state_fields(nxt))
        sample, sample_g, _ = _samplers(buffer, cfg)
        agent, m = hierarchy.learn_low_critics(rnd.learning, agent, sample, sample_g, k_upd, cfg)
        m["stats/planned_steps"] = (use_plan & (mask[:, 0])).mean()
        return (nxt, buffer, agent, key), (m, None)

    (env_state, buffer, agent, key), metrics = rollout.train(
        env_step, hierarchy.actor_catch_up(rnd, lambda buffer: _samplers(buffer, cfg)[2],
                                           ("actor_loss", "imitation"),
                                           actor_extra=imitation_loss(cfg.imitation_weight)),
        (env_state, carry.buffer, carry.agent, key), env.config.episode_length, rnd.group)
    metrics = hierarchy.round_metrics(metrics, env_state, graph)
    metrics.update(low_batches.reward_gap(metrics))
    metrics.update(scoped("stats", graph_m))
    metrics["stats/skip_prob"] = skip_prob(carry.ref_loss, cfg)
    # ddpg_agent.py learn(): the epoch's mean goal_loss sets the next epoch's skipping (0 while
    # not learning: learn_if's metrics are zeros then)
    return Carry(env_state=env_state, buffer=replay.finish_episodes(buffer), agent=agent,
                 graph=graph, ref_loss=metrics["low/imitation"], key=key), metrics


def evaluate(carry: Carry, key: jax.Array, env: Env, cfg: PIGConfig, trace: bool = False):
    """PIG's test agent (``_eval_test_agent``): deterministic, towards the waypoint that a plan
    made at every step and subgoal skipping choose; ``eval_episodes`` to ``env.maze.goal`` and
    as many to goals drawn as in training; ``eval_on_target_frac``: the share of the maze
    episodes' steps spent within ``REACH_EPS`` of the waypoint aimed at. ``no_plan_*``: pi(s, g)
    alone on the maze episodes (``_eval_test_agent_no_plan``), the policy without the planner it
    imitates (:func:`hierarchy.low_policy`). ``trace``: also every planned step's record
    (:func:`rollout.traced`)."""
    n = cfg.eval_episodes
    k_start, k_skip = jax.random.split(key)
    s0 = rollout.start_states(env, k_start, n)

    def policy(memory, s, k):
        target, _, mask = _plan_step(carry.agent, carry.graph, s, carry.ref_loss, k, cfg)
        a = gc_td3.act(carry.agent, s.obs, target, key, explore=False)
        # standing on a waypoint it still aims at: the plan holds the agent where it is
        on_target = (mask[:, 0] & (jnp.linalg.norm(target - s.info["achieved_goal"], axis=-1)
                                   < planner.REACH_EPS))
        return memory, rollout.Decision(a, target, s.info["goal"],
                                        (mask.sum(-1)[:n].mean(), on_target[:n].mean()))

    steps = env.config.episode_length
    s, (path_len, on_target), rec = rollout.unroll(
        env, s0, policy, steps, xs=jax.random.split(k_skip, steps), trace=trace)
    s_no_plan, _, _ = rollout.unroll(env, jax.tree.map(lambda x: x[:n], s0),
                                     hierarchy.low_policy(carry.agent, key), steps)
    return rollout.report(s, n, rec, trace, {
        "eval/path_length": path_len.mean(), "eval/on_target_frac": on_target.mean(),
        "eval/no_plan_success_rate": s_no_plan.info["success"].mean(),
        "eval/no_plan_goal_distance": s_no_plan.info["goal_distance"].mean()})


def params(carry: Carry) -> tuple:
    """The policy's trained parameters."""
    return gc_td3.trained(carry.agent)


_FUNCTIONS = dict(hparams=hparams, init=init, train_episode=train_episode, evaluate=evaluate,
                  params=params, resolved=resolved)
register(Method("pig", "PIG", PIGOptions, from_run, validate=validate, **_FUNCTIONS))
register(Method("flr_pig", "FLR+PIG", FLRPIGOptions, from_run_flr, validate=validate_flr,
                with_runs=flr.with_runs, base="pig", base_point=(("flr_alpha", 0.0),),
                **_FUNCTIONS))
