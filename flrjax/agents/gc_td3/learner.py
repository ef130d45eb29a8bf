"""The learning state of goal-conditioned TD3 and its updates, on a static schedule.

One :class:`NetworkState` (parameters, Polyak target, Adam state) per network: the actor, the
main twin critics the actor climbs (agent.py ``critic1/2``) and the distance twin critics the
planner reads (agent.py ``critic1_g/2_g``). The reference makes one optimisation step per
environment step, per env (algo.py ``low_agent_optimize``, ``n_batches = 1``): critics,
distance critics, the actor on every 2nd step, targets on every 10th. Here::

    steps, actor_updates = schedule(updates_per_iter, actor_update_freq)  # (2, 1) in the paper
    # every env step:          learn(state, sample, k, critic_updates=updates_per_iter,
    #                                actor_updates=0, sample_g=sample_g)
    # after every `steps` steps: learn(state, sample, k, critic_updates=0,
    #                                  actor_updates=actor_updates)

with ``sample`` / ``sample_g`` the caller's HER batches (replay.py ``LowReplay.sample`` /
``sample_g``: ``future_p`` 0.8 / 1.0, ``future_step`` 150) and their rewards.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import optax
from brax.training.acme import running_statistics

from flrjax import networks
from flrjax.agents.gc_td3.losses import (
    ActorExtra,
    Metrics,
    actor_loss,
    critic_g_target,
    critic_loss,
    critic_target,
)
from flrjax.agents.gc_td3.networks import atom_values, make_networks, state_size
from flrjax.agents.gc_td3.state import AgentState, Hparams, NetworkState, Params, TD3Config

Array = jax.Array
#: The floor of a normalised input's standard deviation (:attr:`TD3Config.obs_norm`): the
#: ``eps`` of DHRL's normalizer.py.
OBS_STD_MIN = 1e-2
Sampler = Callable[["AgentState", Array], Mapping[str, Array]]
"""``sample(agent, key) -> batch``: a training batch with its rewards (see :func:`learn`)."""


def _adam(lr: Array | float) -> optax.GradientTransformation:
    """Adam (torch's defaults == optax's) with a traced learning rate: its state does not
    depend on it, and its update multiplies by ``-lr`` as with a fixed one."""
    return optax.adam(lr)


def _fresh(params: Params, tx: optax.GradientTransformation) -> NetworkState:
    return NetworkState(params=params, target_params=params, opt_state=tx.init(params))


@functools.partial(jax.jit, static_argnums=(1, 2, 3, 4))
def init(
    key: Array, obs_size: int, goal_size: int, action_size: int, config: TD3Config | None = None,
    hp: Hparams | None = None,
) -> AgentState:
    """Fresh agent: independent inits for actor and the four critics, targets = copies.

    ``config`` and ``hp`` default to :class:`TD3Config` and :meth:`Hparams.create` (the
    reference's AntMaze hyper-parameters). Jitted (sizes and config static, ``hp`` traced);
    ``jax.vmap(lambda k, h: init(k, o, g, a, cfg, h))(keys, hps)`` gives a run-batched state.
    The initial weights come from one uniform draw per network (:func:`networks.init_params`:
    PyTorch's distribution, not its numbers).
    """
    config = TD3Config() if config is None else config
    hp = jax.tree.map(lambda x: jnp.asarray(x, jnp.float32),
                      Hparams.create() if hp is None else hp)
    nets = make_networks(config, action_size)
    k_actor, k_critic, k_critic_g = jax.random.split(key, 3)
    width = state_size(config, obs_size)
    actor_params = networks.init_params(nets.actor, k_actor, jnp.zeros((1, width + goal_size)))
    critic_in = jnp.zeros((1, width + goal_size + action_size))

    def init_twin(critic: networks.Critic, k: Array) -> Params:
        return jax.vmap(lambda kk: networks.init_params(critic, kk, critic_in))(
            jax.random.split(k, 2))

    return AgentState(
        actor=_fresh(actor_params, _adam(hp.lr_actor)),
        critic=_fresh(init_twin(nets.critic, k_critic), _adam(hp.lr_critic)),
        critic_g=_fresh(init_twin(nets.critic_g, k_critic_g), _adam(hp.lr_critic)),
        step=jnp.zeros((), jnp.int32),
        hp=hp,
        config=config,
        action_size=action_size,
        # std_eps as an array: brax's default, a Python 0.0, is a weakly typed leaf
        obs_stats=(running_statistics.init_state(jnp.zeros((obs_size,), jnp.float32),
                                                 std_eps=jnp.zeros((), jnp.float32))
                   if config.obs_norm else None),
    )


def observe(state: AgentState, obs: Array) -> AgentState:
    """With :attr:`TD3Config.obs_norm`, the running statistics of the observations learnt
    from updated with ``obs`` ``[B, obs]`` (Welford's, brax's ``running_statistics``);
    else the state as it is."""
    if not state.config.obs_norm:
        return state
    return state.replace(obs_stats=running_statistics.update(
        state.obs_stats, obs, std_min_value=OBS_STD_MIN))


# Updates (learn.py LowLearner) ---------------------------------------------------------------


def _fit_twin(state: AgentState, twin: NetworkState, batch: Mapping[str, Array], y: Array,
              distance_critics: bool = False) -> tuple[NetworkState, Metrics]:
    """One Adam step of ``twin`` towards the targets ``y`` (:func:`losses.critic_loss`; a
    distribution per row for a categorical main critic, whose mean value is logged)."""
    (loss, q), grads = jax.value_and_grad(critic_loss, has_aux=True)(
        twin.params, state, batch, y, distance_critics)
    updates, opt_state = _adam(state.hp.lr_critic).update(grads, twin.opt_state, twin.params)
    twin = twin.replace(params=optax.apply_updates(twin.params, updates), opt_state=opt_state)
    if y.ndim == 2:  # a categorical target [B, K]
        y = y @ atom_values(state.config)
    return twin, {"loss": loss / 2.0, "q": jnp.mean(q), "q_target": jnp.mean(y)}


def update_critic(
    state: AgentState, batch: Mapping[str, Array], key: Array
) -> tuple[AgentState, Metrics]:
    """learn.py ``update_critic``: one step of the main twin critic on a HER batch (named
    scope ``critic_main``, which the step profile groups kernels by)."""
    with jax.named_scope("critic_main"):
        critic, m = _fit_twin(state, state.critic, batch, critic_target(state, batch, key))
    return state.replace(critic=critic), {
        "critic_loss": m["loss"], "q": m["q"], "q_target": m["q_target"],
        "reward": jnp.mean(batch["reward"])}


def update_critic_g(
    state: AgentState, batch_g: Mapping[str, Array], key: Array
) -> tuple[AgentState, Metrics]:
    """learn.py ``update_critic_g``: one step of the *distance* critics on ``batch_g`` (named
    scope ``critic_g``).

    ``batch_g`` is a second batch in which every goal is relabelled to a future achieved goal
    (replay.py ``LowReplay.sample_g``, ``future_p = low_future_p_g = 1.1``, i.e. always), with
    the reward of that goal. The target is as for the main critics (target actor, min over the
    target g-twins) but clipped to ``<= 0`` only. Only ``acting.distance`` reads these critics;
    the actor never does.
    """
    with jax.named_scope("critic_g"):
        critic_g, m = _fit_twin(state, state.critic_g, batch_g,
                                critic_g_target(state, batch_g, key), distance_critics=True)
    return state.replace(critic_g=critic_g), {
        "critic_g_loss": m["loss"], "q_g": m["q"], "q_g_target": m["q_target"]}


def update_actor(
    state: AgentState, batch: Mapping[str, Array], extra: ActorExtra | None = None
) -> tuple[AgentState, Metrics]:
    """learn.py ``update_actor``: one Adam step on :func:`losses.actor_loss` (current
    critics)."""
    actor = state.actor
    with jax.named_scope("actor_update"):
        (loss, aux), grads = jax.value_and_grad(actor_loss, has_aux=True)(
            actor.params, state, batch, extra)
        updates, opt_state = _adam(state.hp.lr_actor).update(grads, actor.opt_state,
                                                              actor.params)
        actor = actor.replace(params=optax.apply_updates(actor.params, updates),
                              opt_state=opt_state)
    return state.replace(actor=actor), {"actor_loss": loss, **aux}


def _polyak(net: NetworkState, polyak: Array | float) -> NetworkState:
    return net.replace(target_params=jax.tree.map(
        lambda t, o: polyak * t + (1.0 - polyak) * o, net.target_params, net.params))


def update_targets(state: AgentState, polyak: Array | float) -> AgentState:
    """agent.py ``LowAgent.target_update``: Polyak-average the actor and all four critics.

    ``polyak`` 1.0 leaves the targets exactly as they are (``1 * t + 0 * o == t``), which
    :func:`critic_step` uses to mask the update without a branch.
    """
    return state.replace(actor=_polyak(state.actor, polyak),
                         critic=_polyak(state.critic, polyak),
                         critic_g=_polyak(state.critic_g, polyak))


def critic_step(
    state: AgentState,
    batch: Mapping[str, Array],
    key: Array,
    batch_g: Mapping[str, Array] | None = None,
) -> tuple[AgentState, Metrics]:
    """One optimisation step without the actor: main critics on ``batch``, the distance
    critics on ``batch_g`` if given (DHRL), ``step += 1``, and the targets when
    ``step % target_update_freq == 0`` (algo.py ``low_agent_optimize``: after steps 10, 20, ...).

    The target update is masked arithmetically (Polyak factor 1 on other steps), not with
    ``lax.cond``: under ``vmap`` over seeds the step counter is batched and a ``cond`` would
    become a ``select`` that computes both branches anyway. The actor is updated separately,
    once every ``actor_update_freq`` critic steps (:func:`learn`). ``batch`` needs ``obs``,
    ``next_obs``, ``goal`` (relabelled), ``action`` and ``reward`` ``[B]``. With
    :attr:`TD3Config.obs_norm` the batch's ``obs`` first join the input statistics
    (:func:`observe`).
    """
    k, k_g = jax.random.split(key)
    state = observe(state, batch["obs"])
    state, metrics = update_critic(state, batch, k)
    if batch_g is not None:
        state, metrics_g = update_critic_g(state, batch_g, k_g)
        metrics = {**metrics, **metrics_g}
    step = state.step + 1
    do_target = step % state.config.target_update_freq == 0
    with jax.named_scope("target_update"):
        state = update_targets(state, jnp.where(do_target, state.hp.polyak, 1.0)).replace(
            step=step)
    return state, {**metrics, "target_updated": do_target}


def schedule(updates_per_iter: int, actor_update_freq: int) -> tuple[int, int]:
    """(env steps per group, actor updates per group) of the static update schedule.

    Every env step makes ``updates_per_iter`` :func:`critic_step` calls; after a group of env
    steps, the actor makes one update per ``actor_update_freq`` critic steps of the group. The
    reference (one update per step, actor every 2nd) gives groups of 2 steps with 1 actor
    update, on its own batch after the critic steps instead of with step 0's batch (algo.py).
    A static schedule replaces the reference's ``step % actor_update_freq`` test, which under
    ``vmap`` would run the actor update on every step.
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
