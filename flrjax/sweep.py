"""A sweep's points inside the vmapped chunk: each run's swept values as arrays, and each
run's algo config with its values in place (:func:`flrjax.config.sweep_points` lists the
points)."""

from __future__ import annotations

import dataclasses

import numpy as np

from flrjax.algos import higl, pig
from flrjax.config import TrainConfig, sweep_points

#: TrainConfig's swept FLR fields -> their names in :class:`flr.FLRConfig`.
_FLR_CONFIG_NAMES = {"flr_alpha": "alpha", "flr_eps": "eps", "flr_next": "next_subgoal"}


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


def with_values(acfg, values: dict):
    """``acfg`` (any algo's config) with ``values``, the traced ``SWEEP_FIELDS`` of one run of
    a sweep, in their places (``flr_*`` in its FLR settings)."""
    if not values:
        return acfg
    if isinstance(acfg, pig.PIGConfig | higl.HIGLConfig):  # a DHRL config inside
        own = {k.removeprefix("pig_"): v for k, v in values.items() if k.startswith("pig_")}
        rest = {k: v for k, v in values.items() if not k.startswith("pig_")}
        return dataclasses.replace(acfg, base=with_values(acfg.base, rest), **own)
    flr_kw = {_FLR_CONFIG_NAMES[k]: v for k, v in values.items() if k.startswith("flr_")}
    if flr_kw:
        acfg = dataclasses.replace(acfg, flr=dataclasses.replace(acfg.flr, **flr_kw))
    return dataclasses.replace(acfg, **{k: v for k, v in values.items()
                                        if not k.startswith("flr_")})
