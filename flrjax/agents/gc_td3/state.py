"""What goal-conditioned TD3 is and holds: its static settings (:class:`TD3Config`), its traced
per-run numbers (:class:`Hparams`) and its learning state (:class:`AgentState`). The other
modules of :mod:`flrjax.agents.gc_td3` compute on these; this one imports none of them."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import optax
from flax import struct

from flrjax import networks

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
    # n-step returns for the main critics: the caller's sampler gives the batch the rewards
    # of ``n_step`` stored steps summed with discounts, the state after them as ``next_obs``
    # and their ``discount`` (gamma ** steps), which :func:`.losses.td_target` bootstraps
    # with. 1: the reference's one-step target. The distance critics keep one step.
    n_step: int = 1
    # A LayerNorm in every critic's hidden layers (networks.MLP.layer_norm), the distance
    # critics' too. Not the reference's: an opt-in lever. XLA's kernels only (not the fused one).
    critic_layer_norm: bool = False
    # A categorical main critic: each of the twins outputs logits over ``critic_atoms`` values
    # evenly spaced on [-clip_return, 0] (C51's distribution, as FastTD3's critic), and Q is
    # their expectation wherever Q is read (the TD target's twin min, the actor, eq. 5's V).
    # It learns by cross-entropy with the target distribution (:func:`.losses.critic_loss`).
    # 0: the reference's scalar critic. The distance critics stay scalar. Not the
    # reference's: an opt-in lever. XLA's kernels only (not the fused one).
    critic_atoms: int = 0
    # Every network input normalised by running statistics of the observations the agent has
    # learnt from (its batches' ``obs``: :attr:`AgentState.obs_stats`), the goal in the units
    # of the observation's first entries, as brax's agents and FastTD3 normalise. Not the
    # reference's (DHRL's LowAgent never uses its normalizer.py): an opt-in lever.
    obs_norm: bool = False


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


@struct.dataclass
class NetworkState:
    """One network's parameters, their Polyak-averaged target copy and its Adam state.

    A twin critic's parameters have a leading axis of 2 and one Adam over both (Adam is per
    parameter, so this is the reference's two Adams)."""

    params: Params
    target_params: Params
    opt_state: optax.OptState


@struct.dataclass
class AgentState:
    """Everything the agent learns: the actor, the main twin critics (``critic``) and the
    distance twin critics (``critic_g``, trained on fully relabelled batches; only the planner
    reads them). ``step`` counts :func:`critic_step` calls (algo.py ``low_opt_steps``).
    ``hp`` are the run's traced numbers (learning rates, gamma, Polyak, noises); ``config``
    and ``action_size`` are static (not traced). ``obs_stats``: with
    :attr:`TD3Config.obs_norm`, the running mean and standard deviation of the observations
    learnt from (brax's ``RunningStatisticsState``); else None, no leaf."""

    actor: NetworkState
    critic: NetworkState
    critic_g: NetworkState
    step: Array  # int32 []
    hp: Hparams
    config: TD3Config = struct.field(pytree_node=False)
    action_size: int = struct.field(pytree_node=False)
    obs_stats: Any = None


def trained(agent: AgentState) -> tuple:
    """The parameters the agent learns (its networks', not their targets or optimisers)."""
    return agent.actor.params, agent.critic.params, agent.critic_g.params
