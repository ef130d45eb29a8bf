"""A sweep's points inside the vmapped chunk: each run's swept values as arrays
(:func:`flrjax.config.sweep_points` lists the points; :func:`flrjax.config.algo_config` puts
one run's values in its algo's config)."""

from __future__ import annotations

import numpy as np

from flrjax.algos import flr
from flrjax.config import TrainConfig, sweep_points


def _sweep_column(field: str, vals: list) -> np.ndarray:
    """One swept field's per-point values as the array vmapped over runs (``flr_next``: a
    bool, True for the goal)."""
    if field == "flr_next":
        return np.array([v == "goal" for v in vals])
    return np.array(vals, np.int32 if isinstance(vals[0], int) else np.float32)


def run_values(cfg: TrainConfig) -> dict[str, np.ndarray]:
    """Each run's swept values (run r: point r // seeds), vmapped alongside the carry."""
    points = sweep_points(cfg)
    return {k: np.repeat(_sweep_column(k, [p[k] for p in points]), cfg.seeds)
            for k in points[0]}


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
