"""Goal-conditioned TD3: the low-level agent of DHRL, as pure functions over a pytree state.

DHRL's low level is TD3 (twin critics with a clipped double-Q target, target-policy smoothing
noise, delayed actor updates, Polyak-averaged targets) on HER batches, plus a *second* pair of
critics trained on fully relabelled batches that only the graph planner reads (as distances).
Everything here is jit- and vmap-able (``jax.vmap`` over a leading seed axis of
:class:`AgentState`), has static shapes and no Python loop over data.

Reference: jayLEE0301/dhrl_official, cited below as ``main.py`` = ``DHRL/main.py`` (argparse
defaults, the same as ``scripts/AntMaze.sh``), ``learn.py`` = ``DHRL/rl/learn/dhrl.py``
(``LowLearner``), ``agent.py`` = ``DHRL/rl/agent/agent.py`` (``LowAgent``, ``DistCritic``),
``core.py`` = ``DHRL/rl/agent/core.py`` (``Actor``, ``Critic``), ``algo.py`` =
``DHRL/rl/algo/dhrl.py`` (``Algo``), ``replay.py`` = ``DHRL/rl/replay/planner.py``.

The reference makes one optimisation step per environment step, per env (algo.py
``low_agent_optimize``, ``n_batches = 1``): critics, distance critics, the actor on every 2nd
step, targets on every 10th. Here that is :func:`learn` on a static schedule::

    sample   = lambda agent, k: replay.sample(..., future_p=0.8, future_step=150) + reward
    sample_g = lambda agent, k: replay.sample(..., future_p=1.0, future_step=150) + reward
    steps, actor_updates = schedule(updates_per_iter, actor_update_freq)  # (2, 1) in the paper
    # every env step:          learn(state, sample, k, critic_updates=updates_per_iter,
    #                                actor_updates=0, sample_g=sample_g)
    # after every `steps` steps: learn(state, sample, k, critic_updates=0,
    #                                  actor_updates=actor_updates)

Split as in brax ``training/agents/*``: networks (:func:`make_networks`, inputs, critic
parametrisation), losses (:func:`critic_target`, :func:`critic_loss`, :func:`actor_loss`),
updates (:func:`update_critic`, :func:`update_critic_g`, :func:`update_actor`,
:func:`update_targets`, :func:`critic_step`, :func:`learn`) and inference (:func:`act`,
:func:`q_value`, :func:`value`, :func:`distance`).

What belongs to DHRL's *high* level and is not here (learn.py ``HighLearner``, agent.py
``HighAgent``): the subgoal actor ``tanh(.) * subgoal_scale + subgoal_offset`` (use
``networks.Actor(scale=..., offset=...)``), its critic input ``(a - offset) / scale``, its
actor loss without the action-L2 term, and subgoal testing in its replay. The behaviour-cloning
term ``loss_bc = mean((pi(o, future_ag) - a)**2)`` that both learners compute is only logged,
never added to a loss, so neither level uses BC; we leave it out.

Deviations from the reference, and why:
- no input normalisation: DHRL's low level never normalises (its normalizer.py is unused
  there);
- target smoothing noise 0.05 / 30: the reference adds 0.05 in its ±30 action units, our
  actions are in [-1, 1] (gear 30);
- one noise draw for both critics of a twin (the reference draws one per critic; at std
  0.0017 this is immaterial) and one Adam over both critics of a pair (Adam is per parameter,
  so the update is the same);
- the initial weights come from one uniform draw (PyTorch's distribution, not its numbers):
  each separate random call costs compile time on CPU;
- the actor step follows its ``actor_update_freq`` critic steps instead of coming between
  them, on its own batch (the reference: actor on steps 0, 2, 4, ... with that step's batch;
  here after steps 1, 3, 5, ...), and the distance critics step before the targets update
  within a step, as in the reference: a static schedule (:func:`schedule`) instead of a
  ``step % 2`` test, which under ``vmap`` computes the actor update on every step (measured in
  ``benchmarks/train_throughput.py``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import struct

from flrjax import networks

Array = jax.Array
Params = Any
Metrics = dict[str, Array]
CriticName = Literal["main", "g"]
Sampler = Callable[["AgentState", Array], Mapping[str, Array]]
"""``sample(agent, key) -> batch``: a training batch with its rewards (see :func:`learn`)."""

#: Action bound of the reference ant: main.py / AntMaze.sh ``--action_max 30`` (ant.xml motors
#: ``ctrlrange ±30``). Our env takes ``[-1, 1]`` with ``gear=30``: the same torques.
REFERENCE_ACTION_MAX = 30.0
#: learn.py ``critic_loss``: ``n_a = pi_targ(o2, bg) + 0.05 * randn`` in the reference's action
#: units (not scaled by ``action_max``, not clipped).
REFERENCE_TARGET_NOISE = 0.05


@dataclasses.dataclass(frozen=True)
class TD3Config:
    """Hyper-parameters of DHRL's low level; defaults are the reference's AntMaze run.

    Defaults from main.py argparse (identical to AntMaze.sh) unless said otherwise. Frozen and
    hashable: it is a static (compile-time) part of :class:`AgentState`.
    """

    hidden_sizes: tuple[int, ...] = networks.HIDDEN_SIZES  # --hid_size 256, --n_hids 3, relu
    action_max: float | tuple[float, ...] = 1.0  # --action_max 30: env units; ours are [-1, 1]
    # Centre of the action box (the high level's subgoal_offset); actions lie in
    # [action_offset - action_max, action_offset + action_max], per dimension if tuples.
    action_offset: float | tuple[float, ...] = 0.0
    lr_actor: float = 1e-4  # --lr_actor
    lr_critic: float = 1e-3  # --lr_critic (all four critics, learn.py LowLearner.__init__)
    gamma: float = 0.99  # --gamma
    polyak: float = 0.995  # --polyak: target <- polyak * target + (1 - polyak) * online
    actor_update_freq: int = 2  # --actor_update_freq: actor on steps 0, 2, 4, ... (algo.py)
    target_update_freq: int = 10  # --target_update_freq: targets after steps 10, 20, ...
    batch_size: int = 1024  # --batch_size (for the caller's sampler; update takes any B)
    action_l2: float = 0.01  # --action_l2: weight of mean((pi / action_max)**2), learn.py
    noise_eps: float = 0.1  # --noise_eps: Gaussian exploration std, times action_max (algo.py)
    random_eps: float = 0.2  # --random_eps: probability of a uniform random action (algo.py)
    # Target smoothing noise std in *our* action units: 0.05 in the reference's units (learn.py),
    # i.e. 0.05 / 30 of the action range. Not clipped, as in the reference.
    target_noise: float = REFERENCE_TARGET_NOISE / REFERENCE_ACTION_MAX
    clip_return: float = 80.0  # --clip_return: main critics' target clipped to [-80, 0]
    absolute_goal: bool = False  # --absolute_goal off: actor sees goal - obs[:g] (agent.py)
    # agent.py: DistCritic (default) outputs a distance d and Q = -(1 - gamma**d) / (1 - gamma);
    # --use_reverse_dist_func (DistReverseCritic) outputs Q itself.
    dist_critic: bool = True
    q_offset: bool = False  # --q_offset: +1 on the planner distance (agent.py get_dist)
    # For the caller's HER sampler (not used here): main.py --low_future_p 0.8,
    # --low_future_p_g 1.1 (i.e. always relabel), --low_future_step 150.
    future_p: float = 0.8
    future_p_g: float = 1.0
    future_step: int = 150


@struct.dataclass
class AgentState:
    """Everything the low-level agent learns. Critic params have a leading twin axis of 2.

    ``critic_*`` are the TD critics the actor climbs (agent.py ``critic1/2``); ``critic_g_*``
    are the pair trained on fully relabelled batches that the planner reads as distances
    (agent.py ``critic1_g/2_g``). ``step`` counts :func:`update` calls (algo.py
    ``low_opt_steps``). ``config`` and ``action_size`` are static (not traced).
    """

    actor_params: Params
    critic_params: Params
    critic_g_params: Params
    target_actor_params: Params
    target_critic_params: Params
    target_critic_g_params: Params
    actor_opt_state: optax.OptState
    critic_opt_state: optax.OptState
    critic_g_opt_state: optax.OptState
    step: Array  # int32 []
    config: TD3Config = struct.field(pytree_node=False)
    action_size: int = struct.field(pytree_node=False)


# --------------------------------------------------------------------------------------------
# Networks
# --------------------------------------------------------------------------------------------


class TD3Networks(NamedTuple):
    actor: networks.Actor
    critic: networks.Critic


def make_networks(config: TD3Config, action_size: int, dot_dtype: Any = None) -> TD3Networks:
    """Actor ``tanh(.) * action_max`` and scalar critic, both 3x256 ReLU (core.py).

    ``dot_dtype`` (e.g. ``jnp.bfloat16``) rounds the layers' matrix operands for inference
    passes (:class:`networks.TorchDense`); the parameters are the same either way."""
    return TD3Networks(
        actor=networks.Actor(action_size, config.hidden_sizes, scale=config.action_max,
                             offset=config.action_offset, dot_dtype=dot_dtype),
        critic=networks.Critic(config.hidden_sizes, dot_dtype=dot_dtype),
    )


def _actor_tx(config: TD3Config) -> optax.GradientTransformation:
    return optax.adam(config.lr_actor)  # torch Adam defaults == optax defaults


def _critic_tx(config: TD3Config) -> optax.GradientTransformation:
    return optax.adam(config.lr_critic)


@functools.partial(jax.jit, static_argnums=(1, 2, 3, 4))
def init(
    key: Array, obs_size: int, goal_size: int, action_size: int, config: TD3Config | None = None
) -> AgentState:
    """Fresh agent: independent inits for actor and the four critics, targets = copies.

    ``config`` defaults to :class:`TD3Config` (the reference's AntMaze hyper-parameters).
    Jitted (sizes and config static); ``jax.vmap(lambda k: init(k, o, g, a, cfg))(keys)``
    gives a seed-batched state.
    """
    config = TD3Config() if config is None else config
    nets = make_networks(config, action_size)
    k_actor, k_critic, k_critic_g = jax.random.split(key, 3)
    actor_params = networks.init_params(nets.actor, k_actor, jnp.zeros((1, obs_size + goal_size)))
    critic_in = jnp.zeros((1, obs_size + goal_size + action_size))

    def init_twin(k: Array) -> Params:
        return jax.vmap(lambda kk: networks.init_params(nets.critic, kk, critic_in))(
            jax.random.split(k, 2))

    critic_params = init_twin(k_critic)
    critic_g_params = init_twin(k_critic_g)
    return AgentState(
        actor_params=actor_params,
        critic_params=critic_params,
        critic_g_params=critic_g_params,
        target_actor_params=actor_params,
        target_critic_params=critic_params,
        target_critic_g_params=critic_g_params,
        actor_opt_state=_actor_tx(config).init(actor_params),
        critic_opt_state=_critic_tx(config).init(critic_params),
        critic_g_opt_state=_critic_tx(config).init(critic_g_params),
        step=jnp.zeros((), jnp.int32),
        config=config,
        action_size=action_size,
    )


# Inputs (agent.py LowAgent._process_inputs_actor / _process_inputs_critic) ------------------


def actor_input(state: AgentState, obs: Array, goal: Array) -> Array:
    """``[obs, goal - obs[:g]]`` (relative goal; ``[obs, goal]`` with ``absolute_goal``).

    The reference's achieved goal is ``obs[:g]`` (the ant's torso x, y lead its observation).
    No input normalisation: DHRL's LowAgent never uses its normalizer.py.
    """
    g = goal.shape[-1]
    rel = goal if state.config.absolute_goal else goal - obs[..., :g]
    return jnp.concatenate([obs, rel], axis=-1)


def critic_input(state: AgentState, obs: Array, goal: Array, action: Array) -> Array:
    """``[obs, goal, (action - offset) / action_max]``: absolute goal (agent.py), scaled action
    (core.py; agent.py ``HighAgent`` subtracts the subgoal offset)."""
    return jnp.concatenate([obs, goal, unit_action(action, state.config)], axis=-1)


def unit_action(action: Array, cfg: TD3Config) -> Array:
    """Action mapped to ``[-1, 1]``: ``(action - action_offset) / action_max``."""
    return (action - jnp.asarray(cfg.action_offset)) / jnp.asarray(cfg.action_max)


def policy(state: AgentState, actor_params: Params, obs: Array, goal: Array,
           dot_dtype: Any = None) -> Array:
    """Deterministic action ``pi(obs, goal)`` in ``[-action_max, action_max]``."""
    actor = make_networks(state.config, state.action_size, dot_dtype).actor
    return actor.apply(actor_params, actor_input(state, obs, goal))


def critic_outputs(
    state: AgentState, twin_params: Params, obs: Array, goal: Array, action: Array,
    dot_dtype: Any = None,
) -> Array:
    """Raw outputs ``[2, ...]`` of a twin critic (a distance with ``dist_critic``, else Q)."""
    critic = make_networks(state.config, state.action_size, dot_dtype).critic
    x = critic_input(state, obs, goal, action)
    return jax.vmap(critic.apply, in_axes=(0, None))(twin_params, x)


# Critic parametrisation (agent.py DistCritic / DistReverseCritic) ---------------------------


def q_from_output(out: Array, config: TD3Config) -> Array:
    """Q from a critic output: ``-(1 - gamma**d) / (1 - gamma)`` for a distance critic.

    agent.py ``DistCritic.forward``. Written as ``expm1(d log gamma) / (1 - gamma)``.
    """
    if not config.dist_critic:
        return out
    return jnp.expm1(out * jnp.log(config.gamma)) / (1.0 - config.gamma)


def distance_from_output(out: Array, config: TD3Config) -> Array:
    """Steps-to-goal from a critic output (agent.py ``get_dist``), before the twin min/clamp.

    DistCritic: the output itself. DistReverseCritic: ``log(1 + Q (1 - gamma)) / log gamma``
    with Q clamped to ``>= 1 / (gamma - 1) + 1``. ``q_offset`` adds 1 in both.
    """
    gamma = config.gamma
    if config.dist_critic:
        dist = out
    else:
        q = jnp.maximum(out, 1.0 / (gamma - 1.0) + 1.0)
        dist = jnp.log1p(q * (1.0 - gamma)) / jnp.log(gamma)
    return dist + 1.0 if config.q_offset else dist


def _twin(state: AgentState, critic: CriticName, target: bool) -> Params:
    if critic == "main":
        return state.target_critic_params if target else state.critic_params
    if critic == "g":
        return state.target_critic_g_params if target else state.critic_g_params
    raise ValueError(f"critic must be 'main' or 'g', got {critic!r}")


# --------------------------------------------------------------------------------------------
# Losses (learn.py LowLearner)
# --------------------------------------------------------------------------------------------


def critic_target(
    state: AgentState, batch: Mapping[str, Array], key: Array, *, critic: CriticName = "main"
) -> Array:
    """TD target ``r + gamma * min_i Q'_i(s', pi'(s', g) + noise, g)``, clipped, ``[B]``.

    learn.py ``critic_loss`` (``critic="main"``): clipped to ``[-clip_return, 0]``;
    ``critic_loss_g`` (``critic="g"``): the g-critics' targets, clipped to ``<= 0`` only. Both
    use the *target actor* and N(0, target_noise) smoothing noise, unclipped. No termination:
    the reference bootstraps through every transition (goal-reaching never ends an episode).
    """
    cfg = state.config
    next_a = policy(state, state.target_actor_params, batch["next_obs"], batch["goal"])
    next_a = next_a + cfg.target_noise * jax.random.normal(key, next_a.shape, next_a.dtype)
    out = critic_outputs(state, _twin(state, critic, True), batch["next_obs"], batch["goal"],
                         next_a)
    q_next = jnp.min(q_from_output(out, cfg), axis=0)
    y = batch["reward"] + cfg.gamma * q_next
    y = jnp.clip(y, -cfg.clip_return, 0.0) if critic == "main" else jnp.minimum(y, 0.0)
    return jax.lax.stop_gradient(y)


def critic_loss(
    twin_params: Params, state: AgentState, batch: Mapping[str, Array], target: Array
) -> tuple[Array, Array]:
    """Sum over the twins of ``mean((Q_i(s, a, g) - y)**2)``; also returns ``Q [2, B]``.

    The reference steps two Adams on the two losses; one Adam on the summed loss over both
    parameter sets is the same update (Adam is per parameter, the gradients do not mix).
    """
    out = critic_outputs(state, twin_params, batch["obs"], batch["goal"], batch["action"])
    q = q_from_output(out, state.config)
    return jnp.sum(jnp.mean(jnp.square(q - target), axis=-1)), q


ActorExtra = Callable[["AgentState", Params, Array, Mapping[str, Array]],
                      tuple[Array, Metrics]]
"""``extra(state, actor_params, pi[B, A], batch) -> (term, metrics)``: a method's own term
added to the actor loss (HIGL's landmark loss, PIG's imitation), with metrics of its own.
``actor_params`` are the ones being differentiated, ``pi = pi(s, g)`` on the batch."""


def actor_loss(
    actor_params: Params,
    state: AgentState,
    batch: Mapping[str, Array],
    extra: ActorExtra | None = None,
) -> tuple[Array, Metrics]:
    """``-mean Q_1(s, pi(s, g), g) + action_l2 * mean((pi / action_max)**2)`` [+ extra].

    learn.py ``LowLearner.actor_loss``: the first main critic only (agent.py ``forward1``),
    the L2 mean over batch *and* action dimensions. No BC term (it is only logged there).
    """
    cfg = state.config
    pi = policy(state, actor_params, batch["obs"], batch["goal"])
    out = critic_outputs(state, state.critic_params, batch["obs"], batch["goal"], pi)
    q_pi = q_from_output(out[0], cfg)
    l2 = jnp.mean(jnp.square(unit_action(pi, cfg)))
    loss = -jnp.mean(q_pi) + cfg.action_l2 * l2
    metrics = {"q_pi": jnp.mean(q_pi), "action_l2": l2}
    if extra is not None:
        term, extra_metrics = extra(state, actor_params, pi, batch)
        loss = loss + term
        metrics = {**metrics, "actor_extra": term, **extra_metrics}
    return loss, metrics


# --------------------------------------------------------------------------------------------
# Updates
# --------------------------------------------------------------------------------------------


def _critic_step(
    state: AgentState, batch: Mapping[str, Array], key: Array, critic: CriticName
) -> tuple[Params, optax.OptState, Metrics]:
    """One Adam step of a twin critic towards :func:`critic_target` (named scope
    ``critic_main`` or ``critic_g``, which the step profile groups kernels by)."""
    with jax.named_scope(f"critic_{critic}"):
        return _critic_step_unscoped(state, batch, key, critic)


def _critic_step_unscoped(
    state: AgentState, batch: Mapping[str, Array], key: Array, critic: CriticName
) -> tuple[Params, optax.OptState, Metrics]:
    params = _twin(state, critic, False)
    opt_state = state.critic_opt_state if critic == "main" else state.critic_g_opt_state
    y = critic_target(state, batch, key, critic=critic)
    (loss, q), grads = jax.value_and_grad(critic_loss, has_aux=True)(params, state, batch, y)
    updates, opt_state = _critic_tx(state.config).update(grads, opt_state, params)
    params = optax.apply_updates(params, updates)
    metrics = {"loss": loss / 2.0, "q": jnp.mean(q), "q_target": jnp.mean(y)}
    return params, opt_state, metrics


def update_critic(
    state: AgentState, batch: Mapping[str, Array], key: Array
) -> tuple[AgentState, Metrics]:
    """learn.py ``update_critic``: one step of the main twin critic on a HER batch."""
    params, opt_state, m = _critic_step(state, batch, key, "main")
    state = state.replace(critic_params=params, critic_opt_state=opt_state)
    return state, {"critic_loss": m["loss"], "q": m["q"], "q_target": m["q_target"],
                   "reward": jnp.mean(batch["reward"])}


def update_critic_g(
    state: AgentState, batch_g: Mapping[str, Array], key: Array
) -> tuple[AgentState, Metrics]:
    """learn.py ``update_critic_g``: one step of the *distance* critics on ``batch_g``.

    ``batch_g`` is a second batch in which every goal is relabelled to a future achieved goal
    (replay.py ``LowReplay.sample_g``, ``future_p = low_future_p_g = 1.1``, i.e. always), with
    the reward of that goal. The target is as for the main critics (target actor, min over the
    target g-twins) but clipped to ``<= 0`` only. Only :func:`distance` reads these critics;
    the actor never does.
    """
    params, opt_state, m = _critic_step(state, batch_g, key, "g")
    state = state.replace(critic_g_params=params, critic_g_opt_state=opt_state)
    return state, {"critic_g_loss": m["loss"], "q_g": m["q"], "q_g_target": m["q_target"]}


def update_actor(
    state: AgentState, batch: Mapping[str, Array], extra: ActorExtra | None = None
) -> tuple[AgentState, Metrics]:
    """learn.py ``update_actor``: one Adam step on :func:`actor_loss` (current critics)."""
    with jax.named_scope("actor_update"):
        (loss, aux), grads = jax.value_and_grad(actor_loss, has_aux=True)(
            state.actor_params, state, batch, extra
        )
        updates, opt_state = _actor_tx(state.config).update(
            grads, state.actor_opt_state, state.actor_params
        )
        params = optax.apply_updates(state.actor_params, updates)
    state = state.replace(actor_params=params, actor_opt_state=opt_state)
    return state, {"actor_loss": loss, **aux}


def _polyak(target: Params, online: Params, polyak: Array) -> Params:
    return jax.tree.map(lambda t, o: polyak * t + (1.0 - polyak) * o, target, online)


def update_targets(state: AgentState, polyak: Array | float) -> AgentState:
    """agent.py ``LowAgent.target_update``: Polyak-average the actor and all four critics.

    ``polyak`` 1.0 leaves the targets exactly as they are (``1 * t + 0 * o == t``), which
    :func:`critic_step` uses to mask the update without a branch.
    """
    return state.replace(
        target_actor_params=_polyak(state.target_actor_params, state.actor_params, polyak),
        target_critic_params=_polyak(state.target_critic_params, state.critic_params, polyak),
        target_critic_g_params=_polyak(state.target_critic_g_params, state.critic_g_params,
                                       polyak),
    )


def critic_step(
    state: AgentState,
    batch: Mapping[str, Array],
    key: Array,
    batch_g: Mapping[str, Array] | None = None,
) -> tuple[AgentState, Metrics]:
    """One low-level optimisation step without the actor: main critics on ``batch``, the
    distance critics on ``batch_g`` if given (DHRL), ``step += 1``, and the targets when
    ``step % target_update_freq == 0`` (algo.py ``low_agent_optimize``: after steps 10, 20, ...).

    The target update is masked arithmetically (Polyak factor 1 on other steps), not with
    ``lax.cond``: under ``vmap`` over seeds the step counter is batched and a ``cond`` would
    become a ``select`` that computes both branches anyway. The actor is updated separately,
    once every ``actor_update_freq`` critic steps (:func:`learn`). ``batch`` needs ``obs``,
    ``next_obs``, ``goal`` (relabelled), ``action`` and ``reward`` ``[B]``.
    """
    cfg = state.config
    k, k_g = jax.random.split(key)
    state, metrics = update_critic(state, batch, k)
    if batch_g is not None:
        state, metrics_g = update_critic_g(state, batch_g, k_g)
        metrics = {**metrics, **metrics_g}
    step = state.step + 1
    do_target = step % cfg.target_update_freq == 0
    with jax.named_scope("target_update"):
        state = update_targets(state, jnp.where(do_target, cfg.polyak, 1.0)).replace(step=step)
    return state, {**metrics, "target_updated": do_target}


def schedule(updates_per_iter: int, actor_update_freq: int) -> tuple[int, int]:
    """(env steps per group, actor updates per group) of the static update schedule.

    Every env step makes ``updates_per_iter`` :func:`critic_step` calls; after a group of env
    steps, the actor makes one update per ``actor_update_freq`` critic steps of the group. The
    reference (one update per step, actor every 2nd) gives groups of 2 steps with 1 actor
    update. A static schedule replaces the reference's ``step % actor_update_freq`` test, which
    under ``vmap`` would run the actor update on every step.
    """
    if updates_per_iter % actor_update_freq == 0:
        return 1, updates_per_iter // actor_update_freq
    if actor_update_freq % updates_per_iter == 0:
        return actor_update_freq // updates_per_iter, 1
    raise ValueError(f"updates per step ({updates_per_iter}) and actor_update_freq "
                     f"({actor_update_freq}) must divide one another")


def learn(
    state: AgentState,
    sample: Sampler,
    key: Array,
    *,
    critic_updates: int,
    actor_updates: int,
    sample_g: Sampler | None = None,
    actor_extra: ActorExtra | None = None,
) -> tuple[AgentState, Metrics]:
    """``critic_updates`` :func:`critic_step` calls, then ``actor_updates`` actor steps, each on
    a fresh batch from ``sample(state, key)`` (and ``sample_g`` for the distance critics); a
    ``lax.scan`` each, so one compiled update whatever the counts. The sampler sees the agent
    as it is at that update (the FLR labels rewards with its target critic). Returns mean
    metrics, including any ``metrics`` entry the sampler puts in its batch."""
    k_c, k_a = jax.random.split(key)
    metrics: Metrics = {}

    def one_critic(s: AgentState, k: Array) -> tuple[AgentState, Metrics]:
        k_s, k_g, k_u = jax.random.split(k, 3)
        batch_g = None if sample_g is None else dict(sample_g(s, k_g))
        batch = dict(sample(s, k_s))
        extra = batch.pop("metrics", {})
        if batch_g is not None:
            batch_g.pop("metrics", None)
        s, m = critic_step(s, batch, k_u, batch_g)
        return s, {**extra, **{k: v for k, v in m.items() if k != "target_updated"}}

    def one_actor(s: AgentState, k: Array) -> tuple[AgentState, Metrics]:
        batch = dict(sample(s, k))
        batch.pop("metrics", None)
        return update_actor(s, batch, actor_extra)

    if critic_updates:
        state, m = jax.lax.scan(one_critic, state, jax.random.split(k_c, critic_updates))
        metrics.update(m)
    if actor_updates:
        state, m = jax.lax.scan(one_actor, state, jax.random.split(k_a, actor_updates))
        metrics.update(m)
    return state, jax.tree.map(jnp.mean, metrics)


def learn_if(
    learning: Array,
    state: AgentState,
    sample: Sampler,
    key: Array,
    names: tuple[str, ...],
    *,
    critic_updates: int,
    actor_updates: int,
    sample_g: Sampler | None = None,
    actor_extra: ActorExtra | None = None,
) -> tuple[AgentState, Metrics]:
    """:func:`learn` when ``learning``, else the state unchanged; the metrics ``names`` either
    way (zeros when skipped). ``learning`` must be unbatched (e.g. from the episode index):
    then ``lax.cond`` stays a real branch under ``vmap`` over seeds and the skipped updates
    (the initial random rollouts) cost nothing."""

    def run():
        s, m = learn(state, sample, key, critic_updates=critic_updates,
                     actor_updates=actor_updates, sample_g=sample_g, actor_extra=actor_extra)
        return s, {k: m[k] for k in names}

    def skip():
        return state, {k: jnp.zeros((), jnp.float32) for k in names}

    return jax.lax.cond(learning, run, skip)


# --------------------------------------------------------------------------------------------
# Inference
# --------------------------------------------------------------------------------------------


def act(
    state: AgentState,
    obs: Array,
    goal: Array,
    key: Array,
    *,
    explore: bool | Array,
) -> Array:
    """Action ``[..., A]`` in ``action_offset ± action_max`` for ``obs[..., o]``, ``goal[..., g]``.

    With ``explore`` (algo.py ``Algo.get_actions``): ``pi + noise_eps * action_max * N(0, 1)``,
    clipped, then replaced, with probability ``random_eps`` per action vector, by a uniform
    random action. Without: ``pi`` (algo.py ``eval_get_actions``). ``explore`` may be traced,
    a scalar or one flag per row (shape ``obs.shape[:-1]``, e.g. train vs eval envs).
    """
    cfg = state.config
    a_max, offset = jnp.asarray(cfg.action_max), jnp.asarray(cfg.action_offset)
    pi = policy(state, state.actor_params, obs, goal)
    k_noise, k_rand, k_mask = jax.random.split(key, 3)
    noisy = pi + cfg.noise_eps * a_max * jax.random.normal(k_noise, pi.shape, pi.dtype)
    noisy = jnp.clip(noisy, offset - a_max, offset + a_max)
    rand = offset + jax.random.uniform(k_rand, pi.shape, pi.dtype, -1.0, 1.0) * a_max
    use_rand = jax.random.bernoulli(k_mask, cfg.random_eps, pi.shape[:-1])[..., None]
    explored = jnp.where(use_rand, rand, noisy)
    explore = jnp.asarray(explore)
    explore = explore[..., None] if explore.ndim else explore  # per-row flag [...] -> [..., 1]
    return jnp.where(explore, explored, pi)


def q_value(
    state: AgentState,
    obs: Array,
    goal: Array,
    action: Array | None = None,
    *,
    target: bool = False,
    critic: CriticName = "main",
    dot_dtype: Any = None,
) -> Array:
    """``min_i Q_i(s, a, g)`` ``[...]``, with ``a = pi(s, g)`` (target actor if ``target``) when
    ``action`` is None (agent.py ``get_qs(net=0)`` / ``forward``). ``dot_dtype``: see
    :func:`make_networks`."""
    if action is None:
        actor = state.target_actor_params if target else state.actor_params
        action = policy(state, actor, obs, goal, dot_dtype)
    out = critic_outputs(state, _twin(state, critic, target), obs, goal, action, dot_dtype)
    return jnp.min(q_from_output(out, state.config), axis=0)


def value(
    state: AgentState,
    obs: Array,
    goals: Array,
    *,
    dot_dtype: Any = None,
) -> Array:
    """``V(s, g) = min_i Q_i(s, pi(s, g), g)`` of every goal: ``obs[..., o]``, ``goals[..., M, g]``
    -> ``[..., M]``.

    Matches ``rewards.ValueFn`` (``functools.partial(value, state)``) for the forward-looking
    reward's ``V_l(s', sg')``: the *target* main critics and actor, the stable
    estimate TD learning bootstraps from. Not clipped (a distance critic can give Q > 0 where
    it predicts d < 0). ``dot_dtype=jnp.bfloat16`` evaluates it with bf16 matrix operands
    (the FLR's candidate values: a label, read through a max).
    """
    obs_b = jnp.broadcast_to(obs[..., None, :], goals.shape[:-1] + obs.shape[-1:])
    return q_value(state, obs_b, goals, target=True, dot_dtype=dot_dtype)


def distance(state: AgentState, obs: Array, goal: Array) -> Array:
    """Planner distance ``max(min(d_1, d_2), 0)`` ``[...]`` from the g-critics.

    agent.py ``LowAgent._get_dist_*``: the *online* ``critic1_g/2_g`` at ``a = pi(s, g)`` (online
    actor), each converted by :func:`distance_from_output` (``get_dist``, ``q_offset``
    included), min over the twin, clamped at 0. ``functools.partial(distance, state)`` is a
    ``planner.DistFn``.
    """
    action = policy(state, state.actor_params, obs, goal)
    out = critic_outputs(state, state.critic_g_params, obs, goal, action)
    dist = distance_from_output(out, state.config)
    return jnp.maximum(jnp.min(dist, axis=0), 0.0)
