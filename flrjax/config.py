"""What defines a run: :class:`TrainConfig` (the shared flags and the method's own options)
and its sweep points (its checks: :mod:`flrjax.validation`; its sizes' presets:
:mod:`flrjax.presets`).

Every flag is a dataclass field that says what it is (:func:`flrjax.options.flag`): the shared
ones here, a method's own in its options class (:attr:`flrjax.algos.Method.options`). The
command line, the checks and the sweeps are generated from them, so this module names no
method."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import itertools
from typing import Any

from flrjax import algos, envs, networks
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3.state import REFERENCE_ACTION_MAX, REFERENCE_TARGET_NOISE
from flrjax.algos.common import LEARNER as SIZES
from flrjax.algos.common import NUMBERS, num_devices, padded_runs
from flrjax.options import (
    POSITIVE,
    ConfigError,
    Flag,
    Sweepable,
    at_least,
    dashed,
    flag,
    flags_of,
    parse_one,
)

RUN = "run"


def parse_sweep(text: str) -> tuple[tuple[tuple[str, Any], ...], ...]:
    """``--sweep "flr-alpha=0; flr-eps=0.5, flr-alpha=0.001"``: points split by ``;``, each
    a comma-separated list of FIELD=VALUE (flags' names, with - or _)."""
    sweepable = sweep_fields()
    points = []
    for part in text.split(";"):
        point = []
        for item in filter(None, (x.strip() for x in part.split(","))):
            name, eq, value = item.partition("=")
            field = name.strip().removeprefix("--").replace("-", "_")
            if not eq or field not in sweepable:
                raise argparse.ArgumentTypeError(
                    f"{item!r}: each point is FIELD=VALUE[, ...] with FIELD one of "
                    f"{', '.join(f.replace('_', '-') for f in sweepable)}")
            typ = all_flags()[field].type
            try:
                point.append((field, parse_one(typ)(value.strip())))
            except (ValueError, argparse.ArgumentTypeError):
                kind = "an integer" if typ is int else "a number"
                raise argparse.ArgumentTypeError(f"{item!r}: not {kind}") from None
        if point:
            points.append(tuple(point))
    return tuple(points)


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a run. ``steps`` counts env steps per seed (all envs). The
    method's own flags are :attr:`options` (its :attr:`flrjax.algos.Method.options`; None: its
    defaults) and read as attributes too (``cfg.flr_alpha``); build and change a config by
    flag names with :func:`make` and :meth:`replace`."""

    env: str = flag("point3leg", "one of the envs (flrjax.envs.names())", RUN, type=str)
    algo: str = flag(algos.DEFAULT, "the method (flrjax.algos.names())", RUN, type=str)
    seeds: int = flag(1, "seeds trained at once, vmapped", RUN, type=int, check=at_least(1))
    seed: int = flag(0, "base random seed", RUN, type=int)
    steps: int = flag(20_000, "env steps per seed (all its envs); a multiple of envs x "
                              "episode length x episodes per chunk; 1.92e6 and the like are "
                              "accepted", RUN, type=int, check=at_least(1))
    num_envs: int = flag(1, "lockstep envs per seed; shapes the program: one value", SIZES,
                         type=int, check=at_least(1))
    # Gradient updates per env step; the paper protocol (the reference) is 1 with 1 env.
    updates_per_step: float = flag(1.0, "gradient updates per env step (paper protocol: 1 "
                                        "with 1 env)", SIZES)
    episodes_per_chunk: int = flag(5, "episode rounds per jitted chunk (one evaluation each)",
                                   SIZES, type=int, check=at_least(1))
    eval_episodes: int = flag(10, "deterministic test episodes per evaluation (paper: 10)",
                              SIZES, type=int, check=at_least(1))
    batch_size: int = flag(1024, "TD3 batch (reference: 1024); shapes the program: one value",
                           SIZES, type=int, check=at_least(1))
    hidden: int = flag(256, "width of the 3 hidden layers (reference: 256); shapes the "
                            "program: one value", SIZES, type=int, check=at_least(1))
    # The learners' numbers, traced per run (gc_td3.Hparams): a tuple sweeps one.
    lr_actor: float | tuple[float, ...] = flag(
        1e-4, "Adam learning rate of the low level's actor (flat's, PIG's; reference 1e-4); "
              "comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("actor lr", in_state=True), check=POSITIVE)
    lr_critic: float | tuple[float, ...] = flag(
        1e-3, "Adam learning rate of the low level's critics (reference 1e-3); "
              "comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("critic lr", in_state=True), check=POSITIVE)
    polyak: float | tuple[float, ...] = flag(
        0.995, "target networks of every level: t <- polyak t + (1 - polyak) online; "
               "comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("polyak", in_state=True), check=(lambda v: 0 <= v < 1, "in [0, 1)"))
    target_update_freq: int = flag(10, "updates between target-network steps (reference: 10)",
                                   SIZES, type=int, check=at_least(1))
    gamma: float | tuple[float, ...] | None = flag(
        None, "discount of every level (default: the reference's 0.99, HIGL's controller "
              "0.95); comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("γ", gc_td3.Hparams.gamma, in_state=True),
        check=(lambda v: 0 < v < 1, "in (0, 1)"))
    noise_eps: float | tuple[float, ...] = flag(
        0.1, "the low level's Gaussian exploration std, times the action bound (reference "
             "0.1); comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("exploration noise", in_state=True), check=(lambda v: v >= 0, ">= 0"))
    random_eps: float | tuple[float, ...] = flag(
        0.2, "the low level's chance of a uniformly random action while exploring (reference "
             "0.2); comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("random actions", in_state=True),
        check=(lambda v: 0 <= v <= 1, "in [0, 1]"))
    target_noise: float | tuple[float, ...] = flag(
        REFERENCE_TARGET_NOISE / REFERENCE_ACTION_MAX,
        "the low level's target-policy smoothing std (default 0.05/30, the reference's 0.05 "
        "on torques of +-30); comma-separated values sweep it", NUMBERS,
        sweep=Sweepable("target noise", in_state=True), check=(lambda v: v >= 0, ">= 0"))
    buffer_episodes: int = flag(2500, "replay capacity in episodes, per seed; shapes the "
                                      "program: one value", SIZES, type=int, check=at_least(1))
    # A tuple makes the random phase a per-run choice: both of its branches run every step and
    # each run keeps its own, so the random rounds cost as much as learning.
    initial_episodes: int | tuple[int, ...] = flag(
        10, "random-action episodes before learning (DHRL: 200), per seed over all its envs, "
            "in whole rounds of --num-envs (rounded up); comma-separated values sweep it in "
            "one vmapped run", SIZES, type=int, sweep=Sweepable("initial episodes"),
        check=at_least(0))
    episode_length: int | None = flag(None, "override the env's episode length", SIZES,
                                      type=int, check=at_least(2))
    goal_radius: float | None = flag(None, "ant only: training goals within this of the start",
                                     SIZES, check=POSITIVE)
    # Matrix operands of every level's updates (gc_td3.TD3Config.train_precision); None: bf16
    # on a GPU for a method checked with them (algos.Method.train_bf16_gpu). Never swept.
    train_precision: str | None = flag(
        None, "matrix operands of every level's updates (forward and gradients), float32 or "
              "bfloat16 (float32 accumulation, parameters and Adam; default: bfloat16 on a GPU "
              "for the methods checked with it, float32 otherwise)", SIZES, type=str,
        choices=networks.PRECISIONS)
    critic_layer_norm: bool = flag(
        False, "a LayerNorm in every critic's hidden layers (not the reference's; XLA's "
               "kernels, not the fused one)", SIZES, type=bool)
    obs_norm: bool = flag(
        False, "the low level's network inputs normalised by running statistics of the "
               "observations it learns from, as brax's agents and FastTD3 do (not the "
               "reference's)", SIZES, type=bool)
    # Explicit sweep points (--sweep), each ((field, value), ...); a field a point leaves out
    # keeps the run's value. Exclusive with tuple-valued fields.
    sweep: tuple[tuple[tuple[str, Any], ...], ...] | None = flag(
        None, "sweep points, each FIELD=VALUE[, ...], split by ';' (e.g. 'flr-alpha=0; "
              "lr-critic=3e-4'); a field a point omits keeps its flag's value", "sweeps",
        type=str, parse=parse_sweep)
    # GPU: XLA's scatters without atomics (xla_gpu_deterministic_ops), so that a seed gives the
    # same numbers every time, at the cost of a slower step. Never swept.
    deterministic: bool = flag(False, "on a GPU, the same numbers for the same seed every time "
                                      "(XLA's scatters without atomics, which make each step "
                                      "slower); a CPU always repeats", RUN, type=bool)
    out: str | None = flag(None, "run directory (default runs/<env>-<algo>-<date>-<time>)", RUN,
                           type=str)
    checkpoint_every: int = flag(1, "chunks between checkpoints; 0 keeps none", "checkpoints",
                                 type=int, check=at_least(0))
    # Devices the run axis is sharded over; None: every visible one
    devices: int | None = flag(
        None, "devices the runs (seeds x sweep points) are split over, padded with spare runs "
              "to a multiple of it (default: every visible device, at most one per run; with "
              "--distributed every process's)", RUN, type=int)
    options: Any = None  # the method's own flags

    def __post_init__(self):
        """Make :attr:`options` the method's options class, keeping the values of the flags
        it shares with the one given (a changed ``algo``)."""
        if self.algo not in algos.names():
            return  # flrjax.validation.validate names it
        cls = algos.get(self.algo).options
        if type(self.options) is not cls:
            old = {} if self.options is None else _fields(self.options)
            kept = {k: v for k, v in old.items() if k in flags_of(cls)}
            object.__setattr__(self, "options", cls(**kept))

    def __getattr__(self, name: str):
        """A flag of the method's options, as an attribute of the run."""
        options = self.__dict__.get("options")
        if name.startswith("__") or options is None:
            raise AttributeError(name)
        try:
            return getattr(options, name)
        except AttributeError:
            raise AttributeError(f"{self.algo} has no flag {name!r}") from None

    def replace(self, **flags: Any) -> TrainConfig:
        """This config with ``flags`` (shared or the method's own, by name); a flag the
        method does not take is a :class:`ConfigError`."""
        shared = {k: v for k, v in flags.items() if k in SHARED}
        cfg = dataclasses.replace(self, **shared) if shared else self
        own = {k: v for k, v in flags.items() if k not in SHARED}
        if not own:
            return cfg
        if cfg.options is None:
            raise ConfigError(f"unknown algo {cfg.algo!r}; valid: {', '.join(algos.names())}")
        bad = [k for k in own if k not in flags_of(type(cfg.options))]
        if bad:
            raise ConfigError(not_here(bad[0]))
        return dataclasses.replace(cfg, options=dataclasses.replace(cfg.options, **own))

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


#: The shared flags (TrainConfig's fields but ``options``).
SHARED = tuple(flags_of(TrainConfig))


def _fields(obj) -> dict:
    """A dataclass's fields, shallow (``dataclasses.asdict`` would copy)."""
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


def all_flags() -> dict[str, Flag]:
    """Every flag by field name: the registered methods' own (a flag several methods share is
    one field of one options class they all inherit), then the shared ones."""
    out: dict[str, Flag] = {}
    for m in algos.methods():
        for name, f in flags_of(m.options).items():
            out.setdefault(name, f)
    return {**out, **flags_of(TrainConfig)}


def takers(name: str) -> tuple[str, ...]:
    """The methods whose options have the flag ``name`` (every method for a shared one)."""
    if name in SHARED:
        return algos.names()
    return tuple(m.name for m in algos.methods() if name in flags_of(m.options))


def not_here(name: str) -> str:
    """The error for a flag the run's method does not take: the methods that do."""
    return f"{dashed(name)} applies to {', '.join(takers(name))} only"


def flags(cfg: TrainConfig) -> dict[str, Any]:
    """Every flag of the run by name, the shared ones and its method's, as config.json has
    them."""
    return {**{k: getattr(cfg, k) for k in SHARED},
            **({} if cfg.options is None else _fields(cfg.options))}


def run_flags(cfg: TrainConfig) -> dict[str, Flag]:
    """The flags this run's method takes: its own first, then the shared ones."""
    own = {} if cfg.options is None else flags_of(type(cfg.options))
    return {**own, **flags_of(TrainConfig)}


def make(flags: dict[str, Any], *, drop_unset: bool = False) -> TrainConfig:
    """A config from flags by name (the command line's, config.json's); a flag the method
    does not take is a :class:`ConfigError`, unless ``drop_unset`` and it is unset (None or
    its default: a config.json written when every method's flags were one class's)."""
    shared = {k: v for k, v in flags.items() if k in SHARED}
    cfg = TrainConfig(**shared)
    own = {k: v for k, v in flags.items() if k not in SHARED}
    if drop_unset and cfg.options is not None:
        mine, defaults = flags_of(type(cfg.options)), flag_defaults()
        own = {k: v for k, v in own.items()
               if k in mine or not (v is None or k in defaults and v == defaults[k])}
    return cfg.replace(**own)


def flag_defaults() -> dict[str, Any]:
    """Each flag's default: TrainConfig's, or the first registered method's that has it."""
    out = {k: f.default for k, f in TrainConfig.__dataclass_fields__.items() if k in SHARED}
    for m in algos.methods():
        for f in dataclasses.fields(m.options):
            out.setdefault(f.name, f.default)
    return out


def sweep_fields() -> dict[str, Sweepable]:
    """The sweepable flags of every registered method, by name (:class:`Sweepable`)."""
    return {k: f.sweep for k, f in all_flags().items() if f.sweep is not None}


def sweep_points(cfg: TrainConfig) -> list[dict[str, float | int | str]]:
    """The swept values of each point, in run order: ``cfg.sweep``'s points (each completed
    with the run's values of the fields other points set), or the product of the swept
    fields' values (the method's own flags first, then the shared ones, in field order; the
    last field fastest); ``[{}]`` when nothing is swept. Run ``r`` is seed ``r % cfg.seeds``
    of point ``r // cfg.seeds``."""
    sweepable = [k for k, f in run_flags(cfg).items() if f.sweep is not None]
    if cfg.sweep is not None:
        keys = [k for k in sweepable if any(k in dict(p) for p in cfg.sweep)]
        return [{k: dict(p)[k] if k in dict(p) else run_value(cfg, k) for k in keys}
                for p in cfg.sweep]
    swept = [k for k in sweepable if isinstance(getattr(cfg, k), tuple)]
    return [dict(zip(swept, vals, strict=True))
            for vals in itertools.product(*(getattr(cfg, k) for k in swept))]


def run_value(cfg: TrainConfig, field: str) -> float | int | str:
    """A sweepable field's single value in ``cfg`` (:attr:`Sweepable.default` where unset:
    the paper's or the reference's value, or the method's for the env)."""
    v = getattr(cfg, field)
    if v is not None:
        return v
    default = all_flags()[field].sweep.default
    return default(cfg) if callable(default) else default


def run_points(cfg: TrainConfig) -> tuple[dict, ...]:
    """Each run's point (run r: point r // seeds), in run order, then the padding runs'
    (:func:`flrjax.algos.common.padded_runs`): the last run's."""
    points = [p for p in sweep_points(cfg) for _ in range(cfg.seeds)]
    return tuple(points + points[-1:] * (padded_runs(cfg) - cfg.runs))


def point_name(point: dict) -> str:
    """``flr_alpha 0.01, flr_next goal``: a sweep point for messages."""
    return ", ".join(f"{k} {v}" if isinstance(v, str) else f"{k} {v:g}"
                     for k, v in point.items())


@functools.cache
def _default_episode_length(env: str) -> int:
    """The env's own episode length (building an env compiles its MJCF: do it once)."""
    return envs.make(env).config.episode_length


def make_env(cfg: TrainConfig):
    extra = {k: v for k in ("episode_length", "goal_radius")
             if (v := getattr(cfg, k)) is not None}
    return envs.make(cfg.env, **extra)


def algo_config(cfg: TrainConfig, values: dict | None = None, env=None):
    """The method's own config (its :attr:`~flrjax.algos.Method.from_run`) of one run:
    ``cfg`` with the first sweep point's values in place of its swept fields, and ``values``
    in place of those (a point's, or inside the vmapped chunk each run's traced values of the
    fields its config holds). ``env``: ``make_env(cfg)``, if the caller has it."""
    point = {**sweep_points(cfg)[0], **(values or {})}
    return algos.get(cfg.algo).from_run(cfg.replace(**point),
                                        make_env(cfg) if env is None else env)


def program_config(cfg: TrainConfig, values: dict | None = None, env=None):
    """:func:`algo_config` with what depends on all runs of the program
    (:attr:`~flrjax.algos.Method.with_runs`), as the runner's programs use it. Split over
    several devices, every run computes what a method lets some runs skip: picking runs out
    of the run axis would move their state between devices in every update."""
    algo_cfg = algo_config(cfg, values, env)
    if num_devices(cfg) > 1:
        return algo_cfg
    return algos.get(cfg.algo).with_runs(algo_cfg, run_points(cfg))

