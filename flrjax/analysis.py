"""Reading runs for people: metrics CSVs and the records beside them, per-seed tables, sample
standard deviations, mean ± std bands, and the paper's names for methods, envs and metrics.

One module for the trainer's own summaries (:mod:`flrjax.metrics_io`), the plots
(``experiments/plot_curves.py``), the claims (``experiments/claims.py``) and the notebooks. A
run is a run directory (its ``metrics.csv`` and ``config.json``) or a ``NAME.csv`` written by
``experiments/run_grid.py`` (its record in the ``grid.json`` beside it). Rows are the CSV's,
as strings; one row per run (seed x sweep point) per evaluation.
"""

from __future__ import annotations

import csv
import json
import os
import re
import warnings
from collections.abc import Iterable, Sequence

import numpy as np

from flrjax import algos
from flrjax.config import sweep_fields
from flrjax.options import flags_of

Row = dict[str, str]

#: The paper's names of the envs (``--env``); the point mass (not in the paper) runs in the
#: same two layouts: the U-maze of AntMaze4Leg and the 24 x 8 room of AntMaze3Leg.
ENV_NAMES = {"ant3leg": "AntMaze3Leg", "ant4leg": "AntMaze4Leg",
             "point3leg": "PointMaze room", "point4leg": "PointMaze U-maze"}

#: Axis labels of the metrics (metrics.csv's columns), in words with their units; a metric
#: not listed is labelled by its column name.
METRIC_LABELS = {
    "success_rate": "success rate at the goal",
    "no_plan_success_rate": "success rate at the goal, policy alone (no planner)",
    "random_goal_success": "success rate at training-like goals",
    "train_success": "success rate in training episodes",
    "falls": "falls per evaluation (episodes ending fallen)",
    "final_goal_distance": "distance to the goal at the episode's end (m)",
    "random_goal_distance": "distance to a training-like goal at the episode's end (m)",
    "final_torso_z": "torso height at the episode's end (m)",
    "reward_gap": "FLR reward gap: upright − fallen, at a reached subgoal",
    "reach_reward_upright": "reward at a reached subgoal, upright",
    "reach_reward_fallen": "reward at a reached subgoal, fallen",
    "critic_loss": "low-level critic loss",
    "high_critic_loss": "high-level critic loss",
    "q": "low-level Q",
    "high_q": "high-level Q",
    "graph_nodes": "landmark graph nodes",
    "dist_rank_corr": "distance critic's rank correlation with true path lengths",
    "wall_edge_frac": "fraction of graph edges that cross a wall",
    "goal_landmark_gap": "true path from the goal to its nearest landmark (m)",
    "sample_goal_gap": "true path from the goal to the nearest state landmarks are picked from (m)",
    "replay_goal_gap": "true path from the goal to the nearest state in the replay (m)",
    "path_to_goal": "graph connects start and goal (fraction of rebuilds)",
    "plan_found_frac": "fraction of plans that reach the subgoal through the graph",
    "subgoal_progress": "subgoal's progress towards the goal along the maze (m)",
    "period_progress": "progress towards the goal along the maze per subgoal period (m)",
    "subgoal_distance": "true path from the agent to its subgoal (m)",
    "physics_resets": "physics resets per evaluation",
    "wall_time": "wall time (s)",
    "env_steps_per_s": "env steps per second",
    "chunk_s": "seconds of the chunk's training",
    "eval_s": "seconds of the chunk's evaluation",
}

#: Metrics of a body that can fall over (the ant): constant for the point mass, so its plots
#: leave them out.
FALL_METRICS = ("falls", "final_torso_z")

#: Metrics that are rates or fractions, in [0, 1], and counts, lengths, distances and losses,
#: >= 0: a band is clipped to its range. Any other metric is unbounded.
UNIT_METRICS = ("success_rate", "no_plan_success_rate", "random_goal_success", "train_success",
                "reach_fallen_frac", "reach_frac", "eval_on_target_frac",
                "flr_no_candidate_frac", "wall_edge_frac", "path_to_goal", "plan_found_frac")
NONNEGATIVE_METRICS = ("falls", "physics_resets", "graph_nodes", "path_length",
                       "eval_path_length", "final_goal_distance", "random_goal_distance",
                       "no_plan_goal_distance", "critic_loss", "critic_g_loss",
                       "high_critic_loss", "wall_time", "env_steps_per_s", "chunk_s", "eval_s",
                       "goal_landmark_gap", "sample_goal_gap", "replay_goal_gap",
                       "subgoal_distance")
#: Correlations, in [-1, 1].
CORRELATION_METRICS = ("dist_rank_corr",)


# ---------------------------------------------------------------- names


def plural(n: float, noun: str) -> str:
    """``1 seed``, ``2 seeds``, ``0.25 updates``: ``n`` (thousands separated) and ``noun``,
    singular for exactly one."""
    number = f"{n:,}" if isinstance(n, int) else f"{n:,g}"
    return f"{number} {noun}{'' if n == 1 else 's'}"


def env_name(env: str) -> str:
    """The paper's name of an env (:data:`ENV_NAMES`), else ``env`` itself."""
    return ENV_NAMES.get(env, env)


def can_fall(env: str) -> bool:
    """Whether the env's body can fall over: the ant can, the point mass (``point*``) not."""
    return not env.startswith("point")


def metric_label(metric: str, cumulative: bool = False) -> str:
    """An axis label for ``metric`` (:data:`METRIC_LABELS`); ``cumulative``: its sum over
    evaluations, per seed."""
    if cumulative and metric == "falls":
        return "cumulative falls per seed"
    label = METRIC_LABELS.get(metric, metric)
    return f"{label}, summed over evaluations per seed" if cumulative else label


def metric_range(metric: str, cumulative: bool = False) -> tuple[float, float]:
    """The values ``metric`` can take: [0, 1] for a rate or fraction, [0, inf) for a count,
    length, distance or loss (and for a cumulative sum of either), [-1, 1] for a correlation,
    as :data:`UNIT_METRICS`, :data:`NONNEGATIVE_METRICS` and :data:`CORRELATION_METRICS`
    declare them; unbounded otherwise (and a correlation's cumulative sum)."""
    if metric in UNIT_METRICS:
        lo, hi = 0.0, 1.0
    elif metric in NONNEGATIVE_METRICS:
        lo, hi = 0.0, np.inf
    elif metric in CORRELATION_METRICS and not cumulative:
        lo, hi = -1.0, 1.0
    else:
        lo, hi = -np.inf, np.inf
    return lo, np.inf if cumulative else hi


def known_method(algo: str) -> bool:
    """Whether ``algo`` is a registered method (:mod:`flrjax.algos`)."""
    return algo in algos.names()


def method_name(algo: str, point: dict | None = None) -> str:
    """The paper's name of a run's method (:attr:`flrjax.algos.Method.paper_name`) at a sweep
    point: FLR at alpha = 0 is its base method (eq. 1's sparse reward:
    :func:`flrjax.algos.point_method`)."""
    return algos.point_method(algo, point or {}).paper_name


def field_label(field: str) -> str:
    """How a swept field appears in a curve's name (its
    :attr:`~flrjax.options.Sweepable.label`)."""
    fields = sweep_fields()
    return fields[field].label if field in fields else field


def value_text(v: object) -> str:
    """A swept value as a label shows it: a number as it is unless it needs more than 4
    significant digits (the default target noise 0.05/30 as 0.001667), a word as it is."""
    try:
        f = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return str(v)
    short = f"{f:.4g}"
    return str(v) if float(short) == f else short


def point_name(algo: str, point: dict) -> str:
    """A sweep point as the paper names it (:func:`method_name`; the flags of the method's
    own that the point's method lacks, FLR's at alpha = 0, do not apply); other swept values
    follow."""
    method = algos.point_method(algo, point)
    own = flags_of(method.options)
    mine = flags_of(algos.get(algo).options)
    shown = [f"{field_label(k)}={value_text(v)}" for k, v in point.items()
             if k in own or k not in mine]
    return " ".join([method.paper_name, *shown])


def device_name(device: str) -> str:
    """``H100`` for ``NVIDIA H100 80GB HBM3``: a device kind's model number, else as it is."""
    m = re.search(r"\b([A-Z]\d{2,4})\b", device)
    return m.group(1) if m else device.upper() if device.lower() == "cpu" else device


def format_steps(steps: float) -> str:
    """``1.10M`` from 100k steps on, else the number."""
    return f"{steps / 1e6:.2f}M" if steps >= 100_000 else f"{steps:,.0f}"


# ---------------------------------------------------------------- reading runs


def csv_path(run: str) -> str:
    """A run's metrics CSV: ``run`` itself if it is a CSV, else ``run``/metrics.csv."""
    return run if run.endswith(".csv") else os.path.join(run, "metrics.csv")


def read_rows(run: str) -> list[Row]:
    """A run's metrics CSV (:func:`csv_path`) as a list of rows."""
    with open(csv_path(run), newline="") as f:
        return list(csv.DictReader(f))


def has_column(run: str, name: str) -> bool:
    """Whether the run's CSV header has ``name`` (a metric only some methods log)."""
    with open(csv_path(run), newline="") as f:
        return name in next(csv.reader(f), [])


def number(text: str | None) -> float:
    """A CSV cell as a number: NaN where it is empty or absent (a metric a row does not
    have) or not a number."""
    try:
        return float(text) if text else np.nan
    except ValueError:
        return np.nan


def has_data(run: str, name: str) -> bool:
    """Whether some row of the run's CSV has a number for ``name`` (not NaN or empty): a
    metric may be logged and never measured, e.g. the reward gap of a body that never falls."""
    return has_column(run, name) and any(np.isfinite(number(r[name])) for r in read_rows(run))


def run_record(run: str) -> dict:
    """What a run's files say about it (``config``, ``device``, ...): its ``config.json`` (a
    run directory, or the metrics.csv in one) or its record in the ``grid.json`` beside
    ``NAME.csv`` (run NAME, ``run_grid.py``); ``{}`` when there is neither."""
    folder, name = os.path.split(csv_path(run))
    config = os.path.join(folder, "config.json")
    if name == "metrics.csv" and os.path.exists(config):
        with open(config) as f:
            return json.load(f)
    grid = os.path.join(folder, "grid.json")
    if os.path.exists(grid):
        with open(grid) as f:
            for record in json.load(f):
                if record.get("run") == name.removesuffix(".csv"):
                    return record
    return {}


def same(value: str, want: str) -> bool:
    """Whether two cells are equal, as numbers where both are (0.5 is 0.50)."""
    try:
        return float(value) == float(want)
    except ValueError:
        return value == want


def select(rows: Iterable[Row], where: Sequence[tuple[str, str]] = ()) -> list[Row]:
    """The rows whose columns equal ``where``'s values (:func:`same`)."""
    return [r for r in rows if all(same(r[c], v) for c, v in where)]


def sweep_values(run: str) -> list[dict[str, str]]:
    """The swept values of a run, one dict per sweep point in the run's order (``[{}]`` for a
    plain run): its columns that are sweepable flags (:func:`flrjax.config.sweep_fields`)."""
    rows = read_rows(run)
    cols = [c for c in sweep_fields() if rows and c in rows[0]]
    points = dict.fromkeys(tuple(r[c] for c in cols) for r in rows)
    return [dict(zip(cols, p, strict=True)) for p in points] or [{}]


# ---------------------------------------------------------------- tables and bands


def sample_std(x: Sequence[float] | np.ndarray, axis: int = -1) -> np.ndarray | float:
    """Sample standard deviation along ``axis`` (ddof 1, the unbiased variance: the ± of
    every table and band here), NaN where fewer than two values."""
    x = np.asarray(x, dtype=float)
    if x.shape[axis] < 2:
        out = np.full(np.delete(x.shape, axis % x.ndim), np.nan)
        return float(out) if out.ndim == 0 else out
    return x.std(axis=axis, ddof=1)


def table(rows: list[Row], key: str, points: int, seeds: int) -> np.ndarray:
    """``[evaluations, points, seeds]`` of one metric, from rows in the trainer's order."""
    return np.array([float(r[key]) for r in rows]).reshape(-1, points, seeds)


def seed_table(rows: Sequence[Row], metric: str, name: str = "the run"
               ) -> tuple[np.ndarray, list[int], np.ndarray]:
    """(steps, seeds, ``[steps, seeds]`` values) of one sweep point's rows, NaN where a seed
    has no value at a step; ``name`` for the error that two rows fill one cell (rows of two
    sweep points)."""
    steps = np.array(sorted({int(r["step"]) for r in rows}))
    seeds = sorted({int(r["seed"]) for r in rows})
    values = np.full((len(steps), len(seeds)), np.nan)
    for r in rows:
        i, j = np.searchsorted(steps, int(r["step"])), seeds.index(int(r["seed"]))
        if not np.isnan(values[i, j]):
            raise ValueError(f"{name}: two rows for seed {r['seed']} at step {r['step']}; "
                             "a swept column missing from flrjax.config.sweep_fields()?")
        values[i, j] = number(r[metric])
    return steps, seeds, values


def band(values: np.ndarray, cumulative: bool = False, smooth: int = 1
         ) -> tuple[np.ndarray, np.ndarray]:
    """(mean, sample std) over seeds of ``[steps, seeds]`` values at each step: ``cumulative``
    sums each seed over steps first (the paper's fall counts), ``smooth`` averages each seed
    over its last ``smooth`` evaluations (the paper's curves are "smoothed equally", with no
    window given). A step where one seed has a value has std 0; where none has, NaN (a gap)."""
    if cumulative:
        values = np.cumsum(values, axis=0)
    with warnings.catch_warnings():  # a window with no value stays NaN (a gap), silently
        warnings.simplefilter("ignore", RuntimeWarning)
        values = np.array([np.nanmean(values[max(0, i + 1 - smooth):i + 1], axis=0)
                           for i in range(len(values))])
    vals = [v[np.isfinite(v)] for v in values]
    mean = np.array([v.mean() if len(v) else np.nan for v in vals])
    std = np.array([sample_std(v) if len(v) > 1 else 0.0 if len(v) else np.nan for v in vals])
    return mean, std


def curve(run: str, metric: str, cumulative: bool = False, smooth: int = 1,
          where: dict[str, str] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(steps, mean, sample std over seeds) of ``metric`` in a run (:func:`band`), of the
    rows of one sweep point with ``where`` (:func:`sweep_values`)."""
    rows = [r for r in read_rows(run) if all(r[k] == v for k, v in (where or {}).items())]
    steps, _, values = seed_table(rows, metric, run)
    return (steps, *band(values, cumulative, smooth))


def seeds(run: str, where: dict[str, str] | None = None) -> int:
    """How many seeds a run (or one of its sweep points) has."""
    return len({r["seed"] for r in read_rows(run)
                if all(r[k] == v for k, v in (where or {}).items())})
