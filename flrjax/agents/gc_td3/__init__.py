"""Goal-conditioned TD3: the low-level agent of DHRL, as pure functions over a pytree state.

DHRL's low level is TD3 (twin critics with a clipped double-Q target, target-policy smoothing
noise, delayed actor updates, Polyak-averaged targets) on HER batches, plus a *second* pair of
critics trained on fully relabelled batches that only the graph planner reads (as distances).
Everything here is jit- and vmap-able (``jax.vmap`` over a leading seed axis of
:class:`AgentState`), has static shapes and no Python loop over data. Split as brax's
``training/agents/sac``; this package re-exports what the methods use:

- :mod:`.networks`: :class:`TD3Config` (static), :class:`Hparams` (traced per run), the
  networks, their inputs, the critic parametrisation;
- :mod:`.losses`: critic targets, critic loss, actor loss (with a method's :data:`ActorExtra`);
- :mod:`.learner`: :class:`AgentState` (a :class:`NetworkState` per network), :func:`init`,
  the update steps, :func:`schedule`, :func:`learn` / :func:`learn_if`;
- :mod:`.acting`: :func:`act`, :func:`q_value`, :func:`value` (the FLR's V), :func:`distance`
  (the planner's).

Reference: jayLEE0301/dhrl_official, cited in these modules as ``main.py`` = ``DHRL/main.py``
(argparse defaults, the same as ``scripts/AntMaze.sh``), ``learn.py`` =
``DHRL/rl/learn/dhrl.py`` (``LowLearner``), ``agent.py`` = ``DHRL/rl/agent/agent.py``
(``LowAgent``, ``DistCritic``), ``core.py`` = ``DHRL/rl/agent/core.py`` (``Actor``, ``Critic``),
``algo.py`` = ``DHRL/rl/algo/dhrl.py`` (``Algo``), ``replay.py`` = ``DHRL/rl/replay/planner.py``.

What belongs to DHRL's *high* level and is not here (learn.py ``HighLearner``, agent.py
``HighAgent``): the subgoal actor ``tanh(.) * subgoal_scale + subgoal_offset`` (the config's
``action_max`` / ``action_offset``), its critic input ``(a - offset) / scale``, its actor loss
without the action-L2 term, and subgoal testing in its replay. The behaviour-cloning term
``loss_bc = mean((pi(o, future_ag) - a)**2)`` that both learners compute is only logged, never
added to a loss, so neither level uses BC; we leave it out.

Deviations from the reference, and why:
- no input normalisation by default: DHRL's low level never normalises (its normalizer.py is
  unused); :attr:`TD3Config.obs_norm` is an opt-in lever;
- target smoothing noise 0.05 / 30: the reference adds 0.05 in its ±30 action units, our
  actions are in [-1, 1] (gear 30);
- one noise draw for both critics of a twin (the reference draws one per critic; at std
  0.05 / 30 this is immaterial) and one Adam over both critics of a pair (Adam is per
  parameter, so the update is the same);
- the initial weights come from one uniform draw per network (PyTorch's distribution, not its
  numbers): each separate random call costs compile time on CPU;
- the actor step follows its ``actor_update_freq`` critic steps instead of coming between
  them, on its own batch (the reference: actor on steps 0, 2, 4, ... with that step's batch;
  here after steps 1, 3, 5, ...), and the distance critics step before the targets update
  within a step, as in the reference: a static schedule (:func:`schedule`) instead of a
  ``step % 2`` test, which under ``vmap`` computes the actor update on every step
  (docs/benchmarks.md).
"""

from flrjax.agents.gc_td3.acting import act, distance, q_value, value
from flrjax.agents.gc_td3.learner import (
    Sampler,
    init,
    learn,
    learn_if,
    schedule,
)
from flrjax.agents.gc_td3.losses import ActorExtra, actor_loss
from flrjax.agents.gc_td3.networks import policy, unit_action
from flrjax.agents.gc_td3.state import AgentState, Hparams, NetworkState, TD3Config, trained

__all__ = [
    "ActorExtra", "AgentState", "Hparams", "NetworkState", "Sampler", "TD3Config", "act",
    "actor_loss", "distance", "init", "learn", "learn_if", "policy", "q_value", "schedule",
    "trained", "unit_action", "value",
]
