"""A sweep's points inside the vmapped programs: each run's swept values as arrays
(:func:`flrjax.config.sweep_points` lists the points; :func:`flrjax.config.algo_config` puts
one run's values in its method's config, :func:`run_hparams` those its agents' states
carry)."""

from __future__ import annotations

import jax
import numpy as np

from flrjax import algos
from flrjax.config import TrainConfig, algo_config, sweep_fields, sweep_points


def _sweep_column(vals: list, traced) -> np.ndarray:
    """One swept field's per-point values as the array vmapped over runs (a word as its
    :attr:`~flrjax.options.Sweepable.traced` form)."""
    if traced is not None:
        return np.array([traced(v) for v in vals])
    return np.array(vals, np.int32 if isinstance(vals[0], int) else np.float32)


def run_values(cfg: TrainConfig) -> dict[str, np.ndarray]:
    """Each run's swept values (run r: point r // seeds) of the fields the method's config
    holds, vmapped alongside the carry; the agents' states carry the others
    (:func:`run_hparams`)."""
    points, fields = sweep_points(cfg), sweep_fields()
    return {k: np.repeat(_sweep_column([p[k] for p in points], fields[k].traced), cfg.seeds)
            for k in points[0] if not fields[k].in_state}


def run_hparams(cfg: TrainConfig, env=None):
    """Each run's traced learner numbers, as its method's ``init`` puts them in the agents'
    states (its ``hparams``: ``gc_td3.Hparams`` per agent), float32 ``[runs]`` leaves. Built
    per point from Python numbers, so that what the arithmetic derives from them
    (``one_minus_gamma``) rounds once, as a run of that value alone has it."""
    method = algos.get(cfg.algo)
    per_point = [method.hparams(algo_config(cfg, p, env)) for p in sweep_points(cfg)]
    return jax.tree.map(lambda *xs: np.repeat(np.array(xs, np.float32), cfg.seeds), *per_point)
