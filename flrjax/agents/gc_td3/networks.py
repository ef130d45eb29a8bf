"""Networks, inputs and critic parametrisation of goal-conditioned TD3 (DHRL's low level).

The actor and the critics are ``flrjax.networks`` MLPs (core.py ``Actor``, ``Critic``); this
module says what goes into them (agent.py ``LowAgent._process_inputs_*``) and what a critic's
output means (agent.py ``DistCritic``: a distance, or ``DistReverseCritic``: Q itself). The
file names are those of the package docstring (:mod:`flrjax.agents.gc_td3`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from flrjax import networks

if TYPE_CHECKING:
    from flrjax.agents.gc_td3.learner import AgentState

Array = jax.Array
Params = Any

#: Action bound of the reference ant: main.py / AntMaze.sh ``--action_max 30`` (ant.xml motors
#: ``ctrlrange ±30``). Our env takes ``[-1, 1]`` with ``gear=30``: the same torques.
REFERENCE_ACTION_MAX = 30.0
#: learn.py ``critic_loss``: ``n_a = pi_targ(o2, bg) + 0.05 * randn`` in the reference's action
#: units (not scaled by ``action_max``, not clipped).
REFERENCE_TARGET_NOISE = 0.05


@dataclasses.dataclass(frozen=True)
class TD3Config:
    """The static settings of DHRL's low level: shapes, schedules and flags. Defaults are the
    reference's AntMaze run (main.py argparse, identical to AntMaze.sh) unless said otherwise.
    Frozen and hashable: a compile-time part of the agent's state. The numbers the step only
    multiplies or compares with are :class:`Hparams`, traced per run."""

    hidden_sizes: tuple[int, ...] = networks.HIDDEN_SIZES  # --hid_size 256, --n_hids 3, relu
    action_max: float | tuple[float, ...] = 1.0  # --action_max 30: env units; ours are [-1, 1]
    # Centre of the action box (the high level's subgoal_offset); actions lie in
    # [action_offset - action_max, action_offset + action_max], per dimension if tuples.
    action_offset: float | tuple[float, ...] = 0.0
    actor_update_freq: int = 2  # --actor_update_freq: actor on steps 0, 2, 4, ... (algo.py)
    target_update_freq: int = 10  # --target_update_freq: targets after steps 10, 20, ...
    batch_size: int = 1024  # --batch_size (for the caller's sampler; update takes any B)
    clip_return: float = 80.0  # --clip_return: main critics' target clipped to [-80, 0]
    absolute_goal: bool = False  # --absolute_goal off: actor sees goal - obs[:g] (agent.py)
    # agent.py: DistCritic (default) outputs a distance d and Q = -(1 - gamma**d) / (1 - gamma);
    # --use_reverse_dist_func (DistReverseCritic) outputs Q itself.
    dist_critic: bool = True
    q_offset: bool = False  # --q_offset: +1 on the planner distance (agent.py get_dist)
    # For the caller's HER sampler (not used here): main.py --low_future_step 150.
    future_step: int = 150
    # Matrix operands of every pass inside an update (networks.PRECISIONS): the critic losses'
    # forward and backward, the TD target's target networks, the actor loss's actor and
    # critic. Parameters, gradients, Adam and the Polyak targets stay float32; acting and the
    # planner's distances are not updates and keep their own precision. Not the reference's.
    train_precision: str = "float32"
    # Whether a transition that reaches its goal ends the goal's episode: the main critics'
    # TD target is then its reward alone (the batch's ``reached``), with no bootstrap past it
    # (:func:`.losses.td_target`). False: the reference's critic, which bootstraps through
    # every transition. The distance critics always bootstrap (the planner's step counts).
    reach_ends: bool = False
    # The k-step value: the actor and main critics also see the steps left of the goal's
    # ``horizon`` (as ``steps_left / horizon``), and the TD target stops after the last step
    # (:func:`.losses.td_target`). None: no horizon (the reference's). A caller that gives no
    # steps left means a fresh goal: all ``horizon`` steps (eq. 5's V of a next subgoal).
    horizon: int | None = None


@struct.dataclass
class Hparams:
    """The numbers of DHRL's low level that the step multiplies or compares with: traced
    (float32 leaves), one set per run, so that a sweep over them shares one compiled step.
    Defaults are the reference's (main.py argparse). Build it with :meth:`create`, which
    derives ``one_minus_gamma``."""

    lr_actor: float = 1e-4  # --lr_actor
    lr_critic: float = 1e-3  # --lr_critic (all four critics, learn.py LowLearner.__init__)
    gamma: float = 0.99  # --gamma
    polyak: float = 0.995  # --polyak: target <- polyak * target + (1 - polyak) * online
    action_l2: float = 0.01  # --action_l2: weight of mean((pi / action_max)**2), learn.py
    noise_eps: float = 0.1  # --noise_eps: Gaussian exploration std, times action_max (algo.py)
    random_eps: float = 0.2  # --random_eps: probability of a uniform random action (algo.py)
    # Target smoothing noise std in *our* action units: 0.05 in the reference's units (learn.py),
    # i.e. 0.05 / 30 of the action range. Not clipped, as in the reference.
    target_noise: float = REFERENCE_TARGET_NOISE / REFERENCE_ACTION_MAX
    # For the caller's HER sampler (not used here): main.py --low_future_p 0.8,
    # --low_future_p_g 1.1 (i.e. always relabel).
    future_p: float = 0.8
    future_p_g: float = 1.0
    # 1 - gamma, rounded once from a Python float's exact difference, as a float constant in
    # the arithmetic would be (1 - float32(gamma) is not): set by :meth:`create`.
    one_minus_gamma: float = 1.0 - 0.99

    @classmethod
    def create(cls, **values: float) -> Hparams:
        """The defaults with ``values`` in place, and ``one_minus_gamma`` from their gamma."""
        hp = cls(**values)
        return hp.replace(one_minus_gamma=1.0 - hp.gamma)

    def updated(self, **values: float) -> Hparams:
        """These values with ``values`` in place (:meth:`create`)."""
        own = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
               if f.name != "one_minus_gamma"}
        return Hparams.create(**{**own, **values})


class TD3Networks(NamedTuple):
    actor: networks.Actor
    critic: networks.Critic


def make_networks(config: TD3Config, action_size: int, dot_dtype: Any = None) -> TD3Networks:
    """Actor ``tanh(.) * action_max + action_offset`` and scalar critic, 3x256 ReLU (core.py).

    ``dot_dtype`` (e.g. ``jnp.bfloat16``) rounds the layers' matrix operands, in the forward
    pass and its gradients (:class:`networks.TorchDense`); the parameters are the same either
    way. The updates pass :func:`train_dot_dtype`."""
    return TD3Networks(
        actor=networks.Actor(action_size, config.hidden_sizes, scale=config.action_max,
                             offset=config.action_offset, dot_dtype=dot_dtype),
        critic=networks.Critic(config.hidden_sizes, dot_dtype=dot_dtype),
    )


def train_dot_dtype(config: TD3Config) -> Any:
    """``dot_dtype`` of the passes inside an update (``config.train_precision``)."""
    return networks.dot_dtype(config.train_precision)


# Inputs (agent.py LowAgent._process_inputs_actor / _process_inputs_critic) ------------------


def state_size(config: TD3Config, obs_size: int) -> int:
    """Width of :func:`state_input`: the observation, and the steps left with a horizon."""
    return obs_size + (config.horizon is not None)


def state_input(config: TD3Config, obs: Array, steps_left: Array | None = None) -> Array:
    """``obs``, with ``steps_left / horizon`` appended where the config has a horizon
    (``steps_left`` None: a fresh goal, 1)."""
    if config.horizon is None:
        return obs
    frac = (jnp.ones(obs.shape[:-1], obs.dtype) if steps_left is None else
            jnp.broadcast_to(steps_left / config.horizon, obs.shape[:-1]).astype(obs.dtype))
    return jnp.concatenate([obs, frac[..., None]], axis=-1)


def actor_input(config: TD3Config, obs: Array, goal: Array, steps_left: Array | None = None
                ) -> Array:
    """``[obs, goal - obs[:g]]`` (relative goal; ``[obs, goal]`` with ``absolute_goal``), the
    observation as :func:`state_input` gives it.

    The reference's achieved goal is ``obs[:g]`` (the ant's torso x, y lead its observation).
    No input normalisation: DHRL's LowAgent never uses its normalizer.py.
    """
    g = goal.shape[-1]
    rel = goal if config.absolute_goal else goal - obs[..., :g]
    return jnp.concatenate([state_input(config, obs, steps_left), rel], axis=-1)


def critic_input(config: TD3Config, obs: Array, goal: Array, action: Array,
                 steps_left: Array | None = None) -> Array:
    """``[obs, goal, (action - offset) / action_max]``: absolute goal (agent.py), scaled action
    (core.py; agent.py ``HighAgent`` subtracts the subgoal offset), the observation as
    :func:`state_input` gives it."""
    return jnp.concatenate([state_input(config, obs, steps_left), goal,
                            unit_action(action, config)], axis=-1)


def unit_action(action: Array, config: TD3Config) -> Array:
    """Action mapped to ``[-1, 1]``: ``(action - action_offset) / action_max``."""
    return (action - jnp.asarray(config.action_offset)) / jnp.asarray(config.action_max)


def policy(state: AgentState, actor_params: Params, obs: Array, goal: Array,
           dot_dtype: Any = None, steps_left: Array | None = None) -> Array:
    """Deterministic action ``pi(obs, goal)`` in ``action_offset ± action_max`` (with a
    horizon, ``steps_left`` of the goal's; None: all)."""
    actor = make_networks(state.config, state.action_size, dot_dtype).actor
    return actor.apply(actor_params, actor_input(state.config, obs, goal, steps_left))


def critic_outputs(
    state: AgentState, twin_params: Params, obs: Array, goal: Array, action: Array,
    dot_dtype: Any = None, steps_left: Array | None = None,
) -> Array:
    """Raw outputs ``[2, ...]`` of a twin critic (a distance with ``dist_critic``, else Q)."""
    critic = make_networks(state.config, state.action_size, dot_dtype).critic
    x = critic_input(state.config, obs, goal, action, steps_left)
    return jax.vmap(critic.apply, in_axes=(0, None))(twin_params, x)


# Critic parametrisation (agent.py DistCritic / DistReverseCritic) ---------------------------


def q_from_output(out: Array, config: TD3Config, hp: Hparams) -> Array:
    """Q from a critic output: ``-(1 - gamma**d) / (1 - gamma)`` for a distance critic.

    agent.py ``DistCritic.forward``. Written as ``expm1(d log gamma) / (1 - gamma)``.
    """
    if not config.dist_critic:
        return out
    return jnp.expm1(out * jnp.log(hp.gamma)) / hp.one_minus_gamma


def distance_from_output(out: Array, config: TD3Config, hp: Hparams) -> Array:
    """Steps-to-goal from a critic output (agent.py ``get_dist``), before the twin min/clamp.

    DistCritic: the output itself. DistReverseCritic: ``log(1 + Q (1 - gamma)) / log gamma``
    with Q clamped to ``>= 1 / (gamma - 1) + 1``. ``q_offset`` adds 1 in both.
    """
    if config.dist_critic:
        dist = out
    else:
        q = jnp.maximum(out, 1.0 - 1.0 / hp.one_minus_gamma)
        dist = jnp.log1p(q * hp.one_minus_gamma) / jnp.log(hp.gamma)
    return dist + 1.0 if config.q_offset else dist
