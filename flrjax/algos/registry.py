"""The methods the trainer knows, by ``--algo`` name: each registers a :class:`Method` when its
module is imported (``flrjax.algos`` imports the built-in ones), and the config, the command
line, the runner and the output code ask the registry, never a method by its name."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any


def _no_checks(run: Any, points: list[dict], env: Any) -> None:
    return None


def _nothing(cfg: Any) -> dict:
    return {}


def _same(cfg: Any, run_points: tuple[dict, ...]) -> Any:
    return cfg


@dataclasses.dataclass(frozen=True)
class Method:
    """A training method as the trainer drives it: pure per-run functions the runner vmaps over
    runs and scans over episodes, the flags it takes and what its output is called.

    ``run`` below is a :class:`flrjax.config.TrainConfig` (the shared flags, and this method's
    own as attributes too: :attr:`options`), ``config`` the method's static config of one run
    (from :attr:`from_run`), ``carry`` one run's training state. Metrics are named
    ``namespace/name`` by what produced them (:mod:`flrjax.metric_names`): a learner's
    ``low/``, ``high/`` or ``aux/`` (each must stay finite), other training ones ``stats/``,
    :attr:`evaluate`'s ``eval/``.
    """

    name: str  # --algo
    paper_name: str  # in plots, summaries and the start line
    options: type  # frozen dataclass of the method's own flags (flrjax.options.flag fields)
    from_run: Callable  # (run, env) -> config: one run's (one sweep point's) values
    hparams: Callable  # (config) -> the traced numbers init puts in the agents' states
    init: Callable  # (key, env, config, hparams) -> carry
    train_episode: Callable  # (carry, episode, env, config) -> (carry, metrics)
    evaluate: Callable  # (carry, key, env, config, trace=False) -> metrics[, trace]
    params: Callable  # (carry) -> every trained parameter: non-finite ones stop the run
    # (run, points, env) -> None: raise flrjax.options.ConfigError naming the first bad flag;
    # ``points``: each sweep point's values (one empty point if nothing sweeps)
    validate: Callable = _no_checks
    # (config) -> the settings whose defaults depend on the device, as this run has them
    resolved: Callable = _nothing
    # (config, each run's point) -> config: what depends on all runs of one program
    with_runs: Callable = _same
    # The method a sweep point amounts to where its values are ``base_point``'s (FLR at
    # alpha 0 is its base method); its own flags that ``base`` lacks then do not apply.
    base: str | None = None
    base_point: tuple[tuple[str, Any], ...] = ()
    # Whether its updates take bfloat16 matrix operands on a GPU unless --train-precision says
    # otherwise (those whose learning with them was checked).
    train_bf16_gpu: bool = False
    # (carry, key, iters, config) -> the agent after ``iters`` env steps' updates of
    # train_episode's schedule alone, on the carry's buffer (no acting, no physics): what
    # benchmarks/train_throughput.py times as the updates' share; None where not offered.
    learn_alone: Callable | None = None


_METHODS: dict[str, Method] = {}


def register(method: Method) -> Method:
    """Add ``method`` (a name registered again is replaced: a module reloaded, a test's toy)."""
    _METHODS[method.name] = method
    return method


def unregister(name: str) -> None:
    _METHODS.pop(name, None)


def get(name: str) -> Method:
    """The method registered as ``name``; a :class:`KeyError` naming the known ones if none."""
    try:
        return _METHODS[name]
    except KeyError:
        raise KeyError(f"unknown algo {name!r}; valid: {', '.join(_METHODS)}") from None


def names() -> tuple[str, ...]:
    return tuple(_METHODS)


def methods() -> tuple[Method, ...]:
    return tuple(_METHODS.values())


def point_method(name: str, point: dict) -> Method:
    """The method a sweep point of ``name`` amounts to (:attr:`Method.base`)."""
    m = get(name)
    if m.base is not None and m.base_point and all(point.get(k) == v for k, v in m.base_point):
        return get(m.base)
    return m
