"""What defines a run: :class:`TrainConfig`, its presets, its sweep points, the env's
defaults and :func:`validate`."""

from __future__ import annotations

import dataclasses
import functools
import itertools

import jax
import numpy as np

from flrjax import envs, networks, rewards
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value
from flrjax.agents.gc_td3.state import REFERENCE_ACTION_MAX, REFERENCE_TARGET_NOISE
from flrjax.algos import dhrl, flat, flr, hierarchy, higl, num_devices, pig
from flrjax.algos.flr import FLR_DEFAULTS, FLR_FIELDS
from flrjax.algos.hierarchy import DHRL_FIELDS
from flrjax.algos.pig import PIG_DEFAULTS

ALGOS = {"flat": flat, "dhrl": dhrl, "flr_dhrl": dhrl, "pig": pig, "flr_pig": pig,
         "higl": higl}
GRAPH_ALGOS = ("dhrl", "flr_dhrl", "pig", "flr_pig", "higl")
PIG_ALGOS = ("pig", "flr_pig")
#: Methods with a high-level learner: where --high-lr-actor and --high-lr-critic apply.
HIGH_ALGOS = ("dhrl", "flr_dhrl", "higl")
#: Methods whose low level learns from HER batches: where --future-p applies.
HER_ALGOS = ("flat", "dhrl", "flr_dhrl", "pig", "flr_pig")
#: Methods whose low level learns eq. (1)'s or eq. (5)'s reward: where --low-value applies.
REACH_ALGOS = ("dhrl", "flr_dhrl", "pig", "flr_pig")
#: --low-value's readings of the low level's value V^l, and the methods each applies to
#: ("k_step" needs DHRL's subgoal period, the horizon its policy sees).
LOW_VALUES = {"infinite": REACH_ALGOS, "reach_ends": REACH_ALGOS,
              "k_step": ("dhrl", "flr_dhrl")}


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a run. ``steps`` counts env steps per seed (all envs)."""

    env: str = "point3leg"
    algo: str = "flr_dhrl"
    seeds: int = 1
    seed: int = 0
    steps: int = 20_000
    num_envs: int = 1
    # Gradient updates per env step; the paper protocol (the reference) is 1 with 1 env.
    updates_per_step: float = 1.0
    episodes_per_chunk: int = 5
    eval_episodes: int = 10
    batch_size: int = 1024
    hidden: int = 256
    # The learners' numbers, traced per run (gc_td3.Hparams): a tuple sweeps one (SWEEP_FIELDS).
    # Adam's learning rates of the low level (flat's and PIG's one learner) and of the high
    # level (reference: 1e-4 and 1e-3 at both levels).
    lr_actor: float | tuple[float, ...] = 1e-4
    lr_critic: float | tuple[float, ...] = 1e-3
    high_lr_actor: float | tuple[float, ...] = 1e-4
    high_lr_critic: float | tuple[float, ...] = 1e-3
    # Target networks of every level: Polyak factor (traced) and period in updates (static);
    # reference: 0.995 every 10 updates.
    polyak: float | tuple[float, ...] = 0.995
    target_update_freq: int = 10
    # Every level's discount; None: the reference's 0.99 (HIGL's controller: 0.95)
    gamma: float | tuple[float, ...] | None = None
    # The low level's Gaussian exploration std (times the action bound) and target-policy
    # smoothing std (0.05 in the reference's torques of +-30)
    noise_eps: float | tuple[float, ...] = 0.1
    target_noise: float | tuple[float, ...] = REFERENCE_TARGET_NOISE / REFERENCE_ACTION_MAX
    # The low level's HER: chance that a batch's goal is relabelled; None: the reference's 0.8
    future_p: float | tuple[float, ...] | None = None
    buffer_episodes: int = 2500  # replay capacity per seed (1.5M transitions at T = 600)
    initial_episodes: int | tuple[int, ...] = 10  # a tuple sweeps it (SWEEP_FIELDS)
    episode_length: int | None = None  # env override; None = the env's own
    goal_radius: float | None = None  # ant env override: training goals within this of start
    # DHRL (--algo dhrl); None = the env's default (hierarchy.DHRL_ENV_DEFAULTS)
    subgoal_freq: int | None = None  # env steps per subgoal (reference: 40)
    graph_start_steps: int | None = None  # env steps per seed before the first graph
    graph_every_steps: int | None = None  # env steps per seed between graph rebuilds
    cutoff: float | None = None  # max edge length, in estimated steps (reference: 30)
    landmark_eps: float | None = None  # FPS early-stop distance (reference: 10)
    max_landmarks: int | None = None  # at most this many graph nodes (reference: 300)
    landmark_sample: int | None = None  # replay states FPS picks from (reference: 6000)
    # FLR (--algo flr_*); None = the paper's value (flr.FLR_DEFAULTS)
    # A tuple of values sweeps the field inside one vmapped run (see SWEEP_FIELDS).
    flr_alpha: float | tuple[float, ...] | None = None  # eq. (5); the paper: 0.01 = 1 - gamma
    flr_eps: float | tuple[float, ...] | None = None  # next subgoals at >= eps; the paper: 2
    flr_next: str | tuple[str, ...] | None = None  # "sample" (ring at eps) or "goal" (Fig. 5)
    flr_candidates: int | None = None  # next subgoals sampled per transition
    # Reaching transitions per V evaluation (flr.FLRConfig.value_chunk), 0 = all at once;
    # None = flr.FLR_GPU_DEFAULTS on a GPU, FLRConfig's 128 elsewhere. It shapes the compiled
    # step, so it is never swept, and it does not change the rewards (up to float).
    flr_value_chunk: int | None = None
    # Matrix operands of eq. 5's candidate values (flr.FLRConfig.value_dtype), "float32" or
    # "bfloat16"; None = flr.FLR_GPU_DEFAULTS on a GPU, float32 elsewhere. Never swept.
    flr_precision: str | None = None
    # DHRL's subgoal testing (dhrl, flr_dhrl): matrix operands of its landmark-to-subgoal
    # distances, "float32" or "bfloat16"; None = bfloat16 on a GPU
    # (dhrl.SUBGOAL_TEST_GPU_PRECISION), float32 elsewhere. Never swept.
    subgoal_test_precision: str | None = None
    # Matrix operands of both levels' updates (gc_td3.TD3Config.train_precision), "float32" or
    # "bfloat16"; None = bfloat16 for dhrl and flr_dhrl on a GPU (their learning with it was
    # checked: algos.TRAIN_BF16_GPU_ALGOS), float32 elsewhere. Never swept.
    train_precision: str | None = None
    # How the bf16 evaluations of an actor and twin critics on many rows are computed (eq. 5's
    # candidate values, DHRL's subgoal testing; gc_td3.fused_value.KERNELS): "xla" (a kernel
    # per layer) or "fused" (one Pallas kernel; bfloat16 operands only); None = fused on a GPU
    # where the precision is bfloat16 (fused_value.choose), xla elsewhere. Never swept.
    value_kernel: str | None = None
    # PIG's subgoal skipping (--algo pig|flr_pig): each hop past a waypoint with probability
    # jump_temp / imitation loss; None = the reference's (pig.PIG_DEFAULTS); 0 turns it off
    pig_jump_temp: float | tuple[float, ...] | None = None
    # The low level's value (dhrl, flr_dhrl, pig, flr_pig; LOW_VALUES): "infinite", the
    # reference's critic, bootstraps through every transition; "reach_ends": a transition that
    # reaches its subgoal ends the subgoal's episode (gc_td3.TD3Config.reach_ends); "k_step":
    # the policy and critics see the steps left of the subgoal period (gc_td3.TD3Config
    # .horizon), the paper's k-step sum.
    low_value: str = "infinite"
    # Explicit sweep points (--sweep), each ((field, value), ...); a field a point leaves out
    # keeps the run's value. Exclusive with tuple-valued fields.
    sweep: tuple[tuple[tuple[str, float | int | str], ...], ...] | None = None
    # GPU: XLA's scatters without atomics (xla_gpu_deterministic_ops), so that a seed gives the
    # same numbers every time, at the cost of a slower step; on a CPU every run repeats
    # anyway. It shapes the compiled step, so it is never swept.
    deterministic: bool = False
    out: str | None = None
    checkpoint_every: int = 1  # chunks between checkpoints in OUT/checkpoints; 0: none
    # Devices the seed axis is sharded over; None: as many of the visible ones as divide seeds
    devices: int | None = None

    @property
    def horizon(self) -> int:
        return self.episode_length or _default_episode_length(self.env)

    @property
    def steps_per_chunk(self) -> int:
        return self.num_envs * self.horizon * self.episodes_per_chunk

    @property
    def updates_per_iter(self) -> int:
        return round(self.num_envs * self.updates_per_step)

    @property
    def runs(self) -> int:
        """Runs trained at once (the vmapped axis): seeds x sweep points."""
        return self.seeds * len(sweep_points(self))


#: Fields naming a matrix-operand precision (networks.PRECISIONS; None: the default).
PRECISION_FIELDS = ("flr_precision", "subgoal_test_precision", "train_precision")


@dataclasses.dataclass(frozen=True)
class Sweepable:
    """A field that may hold a tuple of values, swept inside one vmapped run: a number the step
    only multiplies, compares or selects with, so every value shares the compiled chunk. Its
    metrics.csv column is its name."""

    label: str  # in plots and messages
    type: type  # one value's type on the command line: float, int or str
    # The value an unset (None) field means, where None is allowed.
    default: float | str | None = None
    # Whether the agents' states carry it (gc_td3.Hparams: the method's init puts each run's
    # value there); else the method's config does, with each run's traced value in the chunk.
    in_state: bool = False


#: The sweepable fields, by name. (A swept ``initial_episodes`` makes the random phase a
#: per-run choice: both of its branches run every step and each run keeps its own, so the
#: random rounds cost as much as learning. ``flr_next`` becomes a per-run choice between the
#: two candidate sets, both drawn.) Sizes (batch, envs, widths, buffer) shape the compiled
#: program and are not here.
SWEEP_FIELDS: dict[str, Sweepable] = {
    "flr_alpha": Sweepable("α", float, FLR_DEFAULTS["flr_alpha"]),
    "flr_eps": Sweepable("ε", float, FLR_DEFAULTS["flr_eps"]),
    "flr_next": Sweepable("next", str, FLR_DEFAULTS["flr_next"]),
    "initial_episodes": Sweepable("initial episodes", int),
    "pig_jump_temp": Sweepable("jump_temp", float, PIG_DEFAULTS["pig_jump_temp"]),
    "lr_actor": Sweepable("actor lr", float, in_state=True),
    "lr_critic": Sweepable("critic lr", float, in_state=True),
    "high_lr_actor": Sweepable("high actor lr", float, in_state=True),
    "high_lr_critic": Sweepable("high critic lr", float, in_state=True),
    "polyak": Sweepable("polyak", float, in_state=True),
    "gamma": Sweepable("γ", float, gc_td3.Hparams.gamma, in_state=True),
    "noise_eps": Sweepable("exploration noise", float, in_state=True),
    "target_noise": Sweepable("target noise", float, in_state=True),
    "future_p": Sweepable("HER future_p", float, gc_td3.Hparams.future_p, in_state=True),
}


def sweep_points(cfg: TrainConfig) -> list[dict[str, float | int | str]]:
    """The swept values of each point, in run order: ``cfg.sweep``'s points (each completed
    with the run's values of the fields other points set), or the product of the swept
    fields' values, the last field fastest; ``[{}]`` when nothing is swept. Run ``r`` is seed
    ``r % cfg.seeds`` of point ``r // cfg.seeds``."""
    if cfg.sweep is not None:
        keys = [k for k in SWEEP_FIELDS if any(k in dict(p) for p in cfg.sweep)]
        return [{k: dict(p)[k] if k in dict(p) else run_value(cfg, k) for k in keys}
                for p in cfg.sweep]
    swept = [k for k in SWEEP_FIELDS if isinstance(getattr(cfg, k), tuple)]
    return [dict(zip(swept, vals, strict=True))
            for vals in itertools.product(*(getattr(cfg, k) for k in swept))]


def run_value(cfg: TrainConfig, field: str) -> float | int | str:
    """A sweepable field's single value in ``cfg`` (:attr:`Sweepable.default` where unset:
    the paper's for ``flr_*``, the reference's for the others)."""
    v = getattr(cfg, field)
    return SWEEP_FIELDS[field].default if v is None else v


def point_name(point: dict) -> str:
    """``flr_alpha 0.01, flr_next goal``: a sweep point for messages."""
    return ", ".join(f"{k} {v}" if isinstance(v, str) else f"{k} {v:g}"
                     for k, v in point.items())


@functools.cache
def _default_episode_length(env: str) -> int:
    """The env's own episode length (building an env compiles its MJCF: do it once)."""
    return envs.make(env).config.episode_length


PRESETS: dict[str, dict] = {
    # A short CPU run on a point mass that shows learning within a few thousand steps, with an
    # evaluation every 800 steps. Small networks and batches; targets follow every update
    # (0.99), as suits a run this short (the reference's 0.995 every 10 updates suits a
    # million steps).
    "quick": dict(steps=9_600, num_envs=4, updates_per_step=1.0, episodes_per_chunk=2,
                  batch_size=256, hidden=64, buffer_episodes=400, initial_episodes=8,
                  polyak=0.99, target_update_freq=1),
    # The reference's scale: 3x256 networks, batch 1024, one update per env step.
    "paper": dict(steps=1_200_000, num_envs=1, updates_per_step=1.0, episodes_per_chunk=5,
                  batch_size=1024, hidden=256, buffer_episodes=2500, initial_episodes=10,
                  polyak=0.995, target_update_freq=10),
    # The reference's networks on 16 lockstep envs per seed with an update every 4 env steps
    # and DHRL's 200 random episodes rounded to the envs (192): the protocol of the GPU
    # figures (docs/results.md).
    "fast": dict(steps=1_920_000, num_envs=16, updates_per_step=0.25, episodes_per_chunk=5,
                 batch_size=1024, hidden=256, buffer_episodes=2500, initial_episodes=192,
                 polyak=0.995, target_update_freq=10),
}


def default_preset() -> str:
    """``--preset auto``: ``fast`` (the GPU figures' protocol) on a GPU, ``quick`` on a CPU."""
    return "quick" if jax.default_backend() == "cpu" else "fast"


class ConfigError(ValueError):
    """A bad flag or combination of flags; shown as one line, without a traceback."""


def validate(cfg: TrainConfig) -> None:
    """Raise :class:`ConfigError` naming the first bad field."""
    if cfg.env not in envs.names():
        raise ConfigError(f"unknown env {cfg.env!r}; valid: {', '.join(envs.names())}")
    if cfg.algo not in ALGOS:
        raise ConfigError(f"unknown algo {cfg.algo!r}; valid: {', '.join(ALGOS)}")
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if any(isinstance(x, float) and not np.isfinite(x) for x in _values(v)):
            raise ConfigError(f"--{f.name.replace('_', '-')} must be a finite number, got {v}")
    _validate_sweep(cfg)
    for name in ("seeds", "steps", "num_envs", "episodes_per_chunk", "eval_episodes",
                 "batch_size", "hidden", "buffer_episodes", "target_update_freq"):
        if getattr(cfg, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be >= 1, got "
                              f"{getattr(cfg, name)}")
    _validate_hparams(cfg)
    if cfg.devices is not None and not (1 <= cfg.devices <= jax.device_count()
                                        and cfg.runs % cfg.devices == 0):
        raise ConfigError(f"--devices must divide the runs (--seeds x sweep values: "
                          f"{cfg.runs}) and be in 1..{jax.device_count()} (the visible "
                          f"devices), got {cfg.devices}")
    for name in PRECISION_FIELDS:
        if getattr(cfg, name) not in (None, *networks.PRECISIONS):
            raise ConfigError(f"--{name.replace('_', '-')} must be one of "
                              f"{', '.join(networks.PRECISIONS)}, got {getattr(cfg, name)!r}")
    if cfg.checkpoint_every < 0:
        raise ConfigError(f"--checkpoint-every must be >= 0, got {cfg.checkpoint_every}")
    if min(_all_values(cfg, "initial_episodes")) < 0:
        raise ConfigError(f"--initial-episodes must be >= 0, got "
                          f"{min(_all_values(cfg, 'initial_episodes'))}")
    if cfg.goal_radius is not None and not cfg.env.startswith("ant"):
        raise ConfigError("--goal-radius applies to the ant envs only")
    if cfg.goal_radius is not None and cfg.goal_radius <= 0:
        raise ConfigError(f"--goal-radius must be > 0, got {cfg.goal_radius}")
    if cfg.episode_length is not None and cfg.episode_length < 2:
        raise ConfigError(f"--episode-length must be >= 2, got {cfg.episode_length}")
    iters = cfg.num_envs * cfg.updates_per_step
    if cfg.updates_per_step <= 0 or abs(iters - round(iters)) > 1e-9:
        raise ConfigError(f"--updates-per-step x --num-envs must be a positive integer "
                          f"(updates per vectorised step), got {iters:g}")
    try:
        group, _ = gc_td3.schedule(cfg.updates_per_iter, gc_td3.TD3Config.actor_update_freq)
    except ValueError as e:
        raise ConfigError(f"--updates-per-step x --num-envs: {e}") from None
    if cfg.horizon % group:
        raise ConfigError(f"the episode length ({cfg.horizon}) must be a multiple of "
                          f"{group}: the actor updates once per {group} env steps")
    dhrl_flags = [k for k in DHRL_FIELDS if getattr(cfg, k) is not None]
    if cfg.algo not in GRAPH_ALGOS and dhrl_flags:
        raise ConfigError(f"--{dhrl_flags[0].replace('_', '-')} applies to the graph algos "
                          f"({', '.join(GRAPH_ALGOS)}) only")
    if cfg.algo in GRAPH_ALGOS:
        _validate_dhrl(cfg, group)
    flr_flags = [k for k in FLR_FIELDS if getattr(cfg, k) is not None]
    if not cfg.algo.startswith("flr_") and flr_flags:
        raise ConfigError(f"--{flr_flags[0].replace('_', '-')} applies to the flr_* algos only")
    if cfg.algo.startswith("flr_"):
        _validate_flr(cfg)
    if cfg.value_kernel is not None:
        _validate_value_kernel(cfg)
    if cfg.subgoal_test_precision is not None and cfg.algo not in ("dhrl", "flr_dhrl"):
        raise ConfigError("--subgoal-test-precision applies to dhrl and flr_dhrl only")
    if cfg.pig_jump_temp is not None or "pig_jump_temp" in sweep_points(cfg)[0]:
        if cfg.algo not in PIG_ALGOS:
            raise ConfigError(f"--pig-jump-temp applies to {' and '.join(PIG_ALGOS)} only")
        if min(_all_values(cfg, "pig_jump_temp")) < 0:
            raise ConfigError(f"--pig-jump-temp must be >= 0, got "
                              f"{min(_all_values(cfg, 'pig_jump_temp'))}")
    if cfg.low_value not in LOW_VALUES:
        raise ConfigError(f"--low-value must be one of {', '.join(LOW_VALUES)}, got "
                          f"{cfg.low_value!r}")
    if cfg.low_value != "infinite" and cfg.algo not in LOW_VALUES[cfg.low_value]:
        raise ConfigError(f"--low-value {cfg.low_value} applies to "
                          f"{', '.join(LOW_VALUES[cfg.low_value])} only")
    if cfg.low_value == "k_step" and cfg.value_kernel == "fused":
        raise ConfigError("--value-kernel fused takes no horizon input: --low-value k_step "
                          "needs --value-kernel xla")
    if cfg.steps % cfg.steps_per_chunk:
        raise ConfigError(f"--steps ({cfg.steps}) must be a multiple of num_envs x episode "
                          f"length x episodes_per_chunk = {cfg.steps_per_chunk}")
    if cfg.buffer_episodes < cfg.num_envs:
        raise ConfigError(f"--buffer-episodes ({cfg.buffer_episodes}) must be >= --num-envs "
                          f"({cfg.num_envs})")
    if cfg.batch_size > cfg.buffer_episodes * cfg.horizon:
        raise ConfigError(f"--batch-size ({cfg.batch_size}) is larger than the replay buffer "
                          f"({cfg.buffer_episodes} episodes x {cfg.horizon} steps)")


def _validate_dhrl(cfg: TrainConfig, group: int) -> None:
    d = hierarchy.settings(cfg)
    for name in ("subgoal_freq", "graph_every_steps", "max_landmarks", "landmark_sample"):
        if d[name] < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be >= 1, got {d[name]}")
    for name in ("cutoff", "landmark_eps"):
        if d[name] <= 0:
            raise ConfigError(f"--{name.replace('_', '-')} must be > 0, got {d[name]}")
    if d["graph_start_steps"] < 0:
        raise ConfigError(f"--graph-start-steps must be >= 0, got {d['graph_start_steps']}")
    if cfg.horizon % d["subgoal_freq"] or d["subgoal_freq"] % group:
        raise ConfigError(f"--subgoal-freq ({d['subgoal_freq']}) must divide the episode "
                          f"length ({cfg.horizon}) and be a multiple of {group} (the actor "
                          f"updates once per {group} env steps)")
    if d["max_landmarks"] > d["landmark_sample"]:
        raise ConfigError(f"--max-landmarks ({d['max_landmarks']}) must be <= "
                          f"--landmark-sample ({d['landmark_sample']})")


#: The learners' traced numbers and the values each may take: (test, what it must be).
HPARAM_RANGES = {
    **dict.fromkeys(("lr_actor", "lr_critic", "high_lr_actor", "high_lr_critic"),
                    (lambda v: v > 0, "> 0")),
    "gamma": (lambda v: 0 < v < 1, "in (0, 1)"),
    "polyak": (lambda v: 0 <= v < 1, "in [0, 1)"),
    **dict.fromkeys(("noise_eps", "target_noise"), (lambda v: v >= 0, ">= 0")),
    "future_p": (lambda v: 0 <= v <= 1, "in [0, 1]"),
}


def _validate_hparams(cfg: TrainConfig) -> None:
    for name, (ok, want) in HPARAM_RANGES.items():
        bad = [v for v in _all_values(cfg, name) if not ok(v)]
        if bad:
            raise ConfigError(f"--{name.replace('_', '-')} must be {want}, got {bad[0]}")
    for name in ("high_lr_actor", "high_lr_critic"):
        if cfg.algo not in HIGH_ALGOS and _all_values(cfg, name) != [
                TrainConfig.__dataclass_fields__[name].default]:
            raise ConfigError(f"--{name.replace('_', '-')} applies to {', '.join(HIGH_ALGOS)} "
                              f"only (methods with a high-level learner)")
    if cfg.algo not in HER_ALGOS and (cfg.future_p is not None
                                      or "future_p" in sweep_points(cfg)[0]):
        raise ConfigError(f"--future-p applies to {', '.join(HER_ALGOS)} only (HIGL's "
                          f"controller learns without HER)")


def _values(v):
    """A field's values: its tuple (a sweep), or the one value."""
    return v if isinstance(v, tuple) else (v,)


def _all_values(cfg: TrainConfig, field: str) -> list:
    """Every value a sweepable field takes over the run's sweep points (an unset one's
    :attr:`Sweepable.default`)."""
    points = sweep_points(cfg)
    if field in points[0]:
        return [p[field] for p in points]
    return [SWEEP_FIELDS[field].default if v is None else v for v in _values(getattr(cfg, field))]


def _validate_sweep(cfg: TrainConfig) -> None:
    tuples = [k for k in SWEEP_FIELDS if isinstance(getattr(cfg, k), tuple)]
    if cfg.sweep is not None:
        if tuples:
            raise ConfigError(f"--sweep lists every point: give --{tuples[0].replace('_', '-')} "
                              "one value (the points' default) or put its values in --sweep")
        if not cfg.sweep:
            raise ConfigError("--sweep needs at least one point")
        for point in cfg.sweep:
            for k, v in point:
                if k not in SWEEP_FIELDS:
                    raise ConfigError(f"--sweep: {k!r} cannot be swept; sweepable: "
                                      f"{', '.join(SWEEP_FIELDS)}")
                if isinstance(v, float) and not np.isfinite(v):
                    raise ConfigError(f"--sweep: {k} must be a finite number, got {v}")
        points = [tuple(p.items()) for p in sweep_points(cfg)]
        if len(set(points)) != len(points):
            raise ConfigError("--sweep: the points must differ, got "
                              + "; ".join(point_name(p) for p in sweep_points(cfg)))
        tuples = list(sweep_points(cfg)[0])
    for k in tuples:
        flag = "--" + k.replace("_", "-")
        if k.startswith("flr_") and not cfg.algo.startswith("flr_"):
            raise ConfigError(f"{flag} applies to the flr_* algos only")
        v = getattr(cfg, k)
        if cfg.sweep is None and len(set(v)) != len(v):
            raise ConfigError(f"{flag}: a sweep needs distinct values, got {v}")
    if isinstance(cfg.flr_eps, tuple) and "goal" in _values(cfg.flr_next):
        raise ConfigError("--flr-eps: a sweep over eps means nothing with --flr-next goal "
                          "(the final goal is the only candidate); list the points with "
                          "--sweep")


def _validate_value_kernel(cfg: TrainConfig) -> None:
    if cfg.value_kernel not in fused_value.KERNELS:
        raise ConfigError(f"--value-kernel must be one of {', '.join(fused_value.KERNELS)}, "
                          f"got {cfg.value_kernel!r}")
    if cfg.algo not in ("dhrl", "flr_dhrl", "flr_pig"):
        raise ConfigError("--value-kernel applies to dhrl, flr_dhrl and flr_pig only")
    if cfg.value_kernel != "fused":
        return
    gpu = jax.default_backend() == "gpu"
    for name, algos, gpu_default in (
            ("flr_precision", ("flr_dhrl", "flr_pig"), flr.FLR_GPU_DEFAULTS["flr_precision"]),
            ("subgoal_test_precision", ("dhrl", "flr_dhrl"), dhrl.SUBGOAL_TEST_GPU_PRECISION)):
        precision = getattr(cfg, name) or (gpu_default if gpu else "float32")
        if cfg.algo in algos and precision != "bfloat16":
            raise ConfigError(f"--value-kernel fused computes with bfloat16 operands: it "
                              f"needs --{name.replace('_', '-')} bfloat16 (the default on a "
                              f"GPU only)")
    if not fused_value.supported(cfg.hidden):
        raise ConfigError(f"--value-kernel fused needs --hidden a power of two >= 16, got "
                          f"{cfg.hidden}")
    if num_devices(cfg) > 1:
        raise ConfigError(f"--value-kernel fused runs on one device; this run is split over "
                          f"{num_devices(cfg)} (use --devices 1 or --value-kernel xla)")


def _validate_flr(cfg: TrainConfig) -> None:
    for point in sweep_points(cfg):
        _validate_flr_values(dataclasses.replace(cfg, **point))


def _validate_flr_values(cfg: TrainConfig) -> None:
    f = flr.settings(cfg)
    if f["flr_next"] not in ("sample", "goal"):
        raise ConfigError(f"--flr-next must be 'sample' or 'goal', got {f['flr_next']!r}")
    if f["flr_candidates"] < 1:
        raise ConfigError(f"--flr-candidates must be >= 1, got {f['flr_candidates']}")
    if cfg.flr_value_chunk is not None and cfg.flr_value_chunk < 0:
        raise ConfigError(f"--flr-value-chunk must be >= 0 (0: the whole batch), got "
                          f"{cfg.flr_value_chunk}")
    try:
        rewards.validate_flr_params(f["flr_alpha"], run_value(cfg, "gamma"),
                                    None if f["flr_next"] == "goal" else f["flr_eps"],
                                    make_env(cfg).config.delta)
    except ValueError as e:
        raise ConfigError(f"--flr-alpha / --flr-eps: {e}") from None


def make_env(cfg: TrainConfig):
    extra = {k: v for k in ("episode_length", "goal_radius")
             if (v := getattr(cfg, k)) is not None}
    return envs.make(cfg.env, **extra)


def algo_config(cfg: TrainConfig, values: dict | None = None, env=None):
    """The algo's own config (its module's ``from_run``) of one run: ``cfg`` with the first
    sweep point's values in place of its swept fields, and ``values`` in place of those (a
    point's, or inside the vmapped chunk each run's traced values of the fields its config
    holds). ``env``: ``make_env(cfg)``, if the caller has it."""
    point = {**sweep_points(cfg)[0], **(values or {})}
    return ALGOS[cfg.algo].from_run(dataclasses.replace(cfg, **point),
                                    make_env(cfg) if env is None else env)
