"""The flags the hierarchical methods (DHRL, PIG, HIGL) share, their defaults per env family
and their checks: the landmark graph and the subgoal period, the high level's learning rates,
the low level's value reading and the value kernel. :func:`settings` fills in the env's
defaults for :func:`flrjax.algos.hierarchy.from_run`.

Reference: jayLEE0301/dhrl_official (``dhrl.py`` = ``DHRL/rl/algo/dhrl.py``, ``AntMaze.sh`` =
``scripts/AntMaze.sh``).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax

from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value
from flrjax.algos.common import LEARNER, NUMBERS, Run
from flrjax.options import POSITIVE, ConfigError, Sweepable, at_least, dashed, flag

#: dhrl.py ``run``: ``n_cycles`` (15) episodes per epoch, of 600 steps with one env.
REFERENCE_EPOCH_STEPS = 15 * 600
#: dhrl.py ``run``: the first graph is built at the end of epoch ``start_planning_epoch + 1``
#: (6, zero-based), after 200 random episodes (120k steps) and 7 epochs (63k steps).
REFERENCE_GRAPH_START_STEPS = 200 * 600 + 7 * REFERENCE_EPOCH_STEPS

#: The graph settings per env family. The ant: the reference's AntMaze run (AntMaze.sh). The
#: point mass moves up to 1 unit per step, several times the ant's pace, and its episodes are 100
#: steps: its distances in steps, time windows and graph sizes are scaled down to match.
DHRL_ENV_DEFAULTS: dict[str, dict] = {
    "ant": dict(subgoal_freq=40, graph_start_steps=REFERENCE_GRAPH_START_STEPS,
                graph_every_steps=REFERENCE_EPOCH_STEPS, cutoff=30.0, landmark_eps=10.0,
                max_landmarks=300, landmark_sample=6000, low_future_step=150),
    "point": dict(subgoal_freq=10, graph_start_steps=2_000, graph_every_steps=800, cutoff=6.0,
                  landmark_eps=3.0, max_landmarks=64, landmark_sample=1000, low_future_step=25),
}
GRAPH = "graph and subgoals, default: the env's"




@dataclasses.dataclass(frozen=True)
class GraphOptions:
    """The flags of the landmark graph and the subgoal period (None: the method's default for
    the env, :data:`DHRL_ENV_DEFAULTS` updated by the options class's ``GRAPH_DEFAULTS``)."""

    #: A method's own defaults per env family ("ant", "point") over DHRL's.
    GRAPH_DEFAULTS: ClassVar[dict[str, dict]] = {}

    subgoal_freq: int | None = flag(None, "env steps per subgoal (ant: 40)", GRAPH, type=int,
                                    check=at_least(1))
    graph_start_steps: int | None = flag(None, "env steps per seed before the first graph",
                                         GRAPH, type=int, check=at_least(0))
    graph_every_steps: int | None = flag(None, "env steps per seed between rebuilds (ant: "
                                               "9000)", GRAPH, type=int, check=at_least(1))
    cutoff: float | tuple[float, ...] | None = flag(
        None, "longest graph edge, in estimated steps (ant: 30); comma-separated values sweep "
              "it", GRAPH, sweep=Sweepable("edge cutoff", lambda run: settings(run)["cutoff"]),
        check=POSITIVE)
    landmark_eps: float | tuple[float, ...] | None = flag(
        None, "FPS stops once every state is this close (ant: 10); comma-separated values "
              "sweep it", GRAPH,
        sweep=Sweepable("landmark spacing", lambda run: settings(run)["landmark_eps"]),
        check=POSITIVE)
    max_landmarks: int | None = flag(None, "most graph nodes (ant: 300)", GRAPH, type=int,
                                     check=at_least(1))
    landmark_sample: int | None = flag(None, "replay states FPS picks from (ant: 6000)", GRAPH,
                                       type=int, check=at_least(1))


#: The high level's Gaussian subgoal noise std, in maze units along the larger half-extent of
#: the subgoal box: dhrl.py ``--subgoal_noise_eps`` (AntMaze.sh: 2).
SUBGOAL_NOISE_EPS = 2.0


def subgoal_noise_default(run: Run) -> float:
    """The high level's subgoal noise where the run sets none: its options class's
    ``SUBGOAL_NOISE_EPS`` (DHRL's :data:`SUBGOAL_NOISE_EPS`, HIGL's manager 1)."""
    return run.options.SUBGOAL_NOISE_EPS


@dataclasses.dataclass(frozen=True)
class HighOptions:
    """The flags of a method with a high-level learner."""

    #: The subgoal noise an unset ``subgoal_noise_eps`` means (a method may have its own).
    SUBGOAL_NOISE_EPS: ClassVar[float] = SUBGOAL_NOISE_EPS

    high_lr_actor: float | tuple[float, ...] = flag(
        1e-4, "the high level's actor learning rate (reference 1e-4); comma-separated values "
              "sweep it", NUMBERS, sweep=Sweepable("high actor lr", in_state=True),
        check=POSITIVE)
    high_lr_critic: float | tuple[float, ...] = flag(
        1e-3, "the high level's critic learning rate (reference 1e-3); comma-separated values "
              "sweep it", NUMBERS, sweep=Sweepable("high critic lr", in_state=True),
        check=POSITIVE)
    subgoal_noise_eps: float | tuple[float, ...] | None = flag(
        None, "the high level's Gaussian subgoal noise std in maze units (default: DHRL's 2, "
              "HIGL's manager 1); comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("subgoal noise", subgoal_noise_default, in_state=True),
        check=(lambda v: v >= 0, ">= 0"))


#: The readings of the low level's value V^l (--low-value; flr.py's docstring).
LOW_VALUES = ("infinite", "reach_ends", "k_step")


@dataclasses.dataclass(frozen=True)
class LowValueOptions:
    """The flag of a method whose low level learns eq. (1)'s or eq. (5)'s reward."""

    low_value: str = flag(
        "infinite", "the low level's value: 'infinite' bootstraps through every transition "
                    "(DHRL's code, the default), 'reach_ends' ends a subgoal's episode where "
                    "the transition reaches it, 'k_step' sums the subgoal period's k steps "
                    "(the paper's V^l: the policy sees the steps left; DHRL's subgoal period)",
        LEARNER, type=str, choices=LOW_VALUES)
    n_step: int = flag(
        1, "env steps the low level's main critics' TD target sums rewards over before it "
           "bootstraps (n-step returns along the stored trajectory, under the batch's goal; "
           "fewer near an episode's end); 1: the reference's one-step target. Not the "
           "paper's: an opt-in lever, with --low-value infinite", LEARNER, type=int,
        check=at_least(1))
    critic_atoms: int = flag(
        0, "the low level's main critics as categorical distributions over this many values "
           "on [-clip_return, 0], learned by cross-entropy (C51, as FastTD3's critic); Q, "
           "eq. 5's V and the actor read their expectation; 0: the reference's scalar "
           "critics. Not the paper's: an opt-in lever (XLA's kernels for eq. 5)", LEARNER,
        type=int, check=(lambda v: v == 0 or v >= 2, "0 or >= 2"))


@dataclasses.dataclass(frozen=True)
class KernelOptions:
    """The flag of a method that evaluates an actor and twin critics on many rows at once
    (eq. 5's candidate values, DHRL's subgoal testing)."""

    value_kernel: str | None = flag(
        None, "eq. 5's candidate values and subgoal testing's distances (an actor and twin "
              "critics on many rows) as one XLA kernel per layer ('xla') or one fused kernel "
              "('fused', bfloat16 operands; default: fused on GPUs, xla on a CPU)",
        LEARNER, type=str, choices=fused_value.KERNELS)


def validate_kernel(run: Run, precisions: dict[str, str]) -> None:
    """``--value-kernel fused``: bfloat16 operands (``precisions``: each flag's value as the
    run resolves it), a width the kernel tiles, critics without LayerNorm."""
    if run.value_kernel != "fused":
        return
    for name, precision in precisions.items():
        if precision != "bfloat16":
            raise ConfigError(f"--value-kernel fused computes with bfloat16 operands: it needs "
                              f"{dashed(name)} bfloat16 (the default on a GPU only)")
    if not fused_value.supported(run.hidden):
        raise ConfigError(f"--value-kernel fused needs --hidden a power of two >= 16, got "
                          f"{run.hidden}")
    if run.critic_layer_norm:
        raise ConfigError("--value-kernel fused has no LayerNorm: drop --critic-layer-norm or "
                          "use --value-kernel xla")
    if getattr(run, "critic_atoms", 0):
        raise ConfigError("--value-kernel fused reads scalar critics: drop --critic-atoms or "
                          "use --value-kernel xla")


def gpu_default(value: str | None, gpu_value: str) -> str:
    """A precision flag's value as the run has it: ``value``, else ``gpu_value`` on a GPU and
    float32 elsewhere."""
    if value is not None:
        return value
    return gpu_value if jax.default_backend() == "gpu" else "float32"


def settings(run: Run) -> dict:
    """The run's :class:`GraphOptions` with its method's defaults for the env filled in."""
    family = "ant" if run.env.startswith("ant") else "point"
    own = run.options.GRAPH_DEFAULTS.get(family, {})
    base = {**DHRL_ENV_DEFAULTS[family], **own}
    return {k: (v if getattr(run, k, None) is None else getattr(run, k)) for k, v in base.items()}


def validate(run: Run) -> None:
    """The graph's and the subgoal period's flags against each other and the episode."""
    d = settings(run)
    group, _ = gc_td3.schedule(run.updates_per_iter, gc_td3.TD3Config.actor_update_freq)
    if run.horizon % d["subgoal_freq"] or d["subgoal_freq"] % group:
        raise ConfigError(f"--subgoal-freq ({d['subgoal_freq']}) must divide the episode "
                          f"length ({run.horizon}) and be a multiple of {group} (the actor "
                          f"updates once per {group} env steps)")
    if getattr(run, "n_step", 1) > 1 and run.low_value != "infinite":
        raise ConfigError(f"--n-step {run.n_step} needs --low-value infinite (the steps "
                          f"would run past where {run.low_value} ends the value)")
    if d["max_landmarks"] > d["landmark_sample"]:
        raise ConfigError(f"--max-landmarks ({d['max_landmarks']}) must be <= "
                          f"--landmark-sample ({d['landmark_sample']})")


def validate_low_value(run: Run, allowed: tuple[str, ...], why: str = "") -> None:
    """``--low-value``: one of the readings this method has (``why``: why not the others)."""
    if run.low_value not in allowed:
        raise ConfigError(f"{dashed('low_value')} {run.low_value}: {run.algo} takes "
                          f"{', '.join(allowed)}{f' ({why})' if why else ''}")


def high_numbers(run: Run) -> dict:
    """The high level's learning rates and subgoal noise (maze units;
    :func:`subgoal_noise_default` where the run sets none) from the run's
    :class:`HighOptions`, for :func:`flrjax.algos.hierarchy.high_hparams`."""
    noise = (subgoal_noise_default(run) if run.subgoal_noise_eps is None
             else run.subgoal_noise_eps)
    return dict(lr_actor=run.high_lr_actor, lr_critic=run.high_lr_critic,
                subgoal_noise_eps=noise)
