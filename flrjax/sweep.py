"""A sweep's points inside the vmapped programs: each run's swept values as arrays
(:func:`flrjax.config.sweep_points` lists the points; :func:`flrjax.config.algo_config` puts
one run's values in its algo's config, :func:`run_hparams` those its agents' states carry)."""

from __future__ import annotations

import jax
import numpy as np

from flrjax.algos import flr
from flrjax.config import ALGOS, SWEEP_FIELDS, TrainConfig, algo_config, sweep_points


def _sweep_column(field: str, vals: list) -> np.ndarray:
    """One swept field's per-point values as the array vmapped over runs (``flr_next``: a
    bool, True for the goal)."""
    if field == "flr_next":
        return np.array([v == "goal" for v in vals])
    return np.array(vals, np.int32 if isinstance(vals[0], int) else np.float32)


def run_values(cfg: TrainConfig) -> dict[str, np.ndarray]:
    """Each run's swept values (run r: point r // seeds) of the fields the method's config
    holds, vmapped alongside the carry; the agents' states carry the others
    (:func:`run_hparams`)."""
    points = sweep_points(cfg)
    return {k: np.repeat(_sweep_column(k, [p[k] for p in points]), cfg.seeds)
            for k in points[0] if not SWEEP_FIELDS[k].in_state}


def run_hparams(cfg: TrainConfig, env=None):
    """Each run's traced learner numbers, as its method's ``init`` puts them in the agents'
    states (its ``hparams``: ``gc_td3.Hparams`` per agent), float32 ``[runs]`` leaves. Built
    per point from Python numbers, so that what the arithmetic derives from them
    (``one_minus_gamma``) rounds once, as a run of that value alone has it."""
    algo = ALGOS[cfg.algo]
    per_point = [algo.hparams(algo_config(cfg, p, env)) for p in sweep_points(cfg)]
    return jax.tree.map(lambda *xs: np.repeat(np.array(xs, np.float32), cfg.seeds), *per_point)


def flr_active_runs(cfg: TrainConfig) -> tuple[bool, ...] | None:
    """Per run (run r: point r // seeds), is its FLR alpha positive? None unless some run's is
    0 (DHRL as a sweep's alpha = 0 point, or --flr-alpha 0) in an ``flr_*`` run: eq. 5's
    candidate values are then computed for the other runs alone
    (:attr:`flrjax.algos.flr.FLRConfig.active_runs`)."""
    if not cfg.algo.startswith("flr_"):
        return None
    alpha = flr.settings(cfg)["flr_alpha"]
    active = tuple(bool(p.get("flr_alpha", alpha) > 0) for p in sweep_points(cfg)
                   for _ in range(cfg.seeds))
    return None if all(active) else active
