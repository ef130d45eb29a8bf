"""Plot a metric of one or more runs against env steps: mean ± std over seeds.

    python experiments/plot_curves.py RUN_DIR [RUN_DIR ...] --metric success_rate --out fig.png

A run that swept ``--flr-alpha``, ``--flr-eps``, ``--flr-next``, ``--initial-episodes`` or
``--pig-jump-temp`` (a column of that name in its CSV) gives one curve per sweep point, in the
run's order;
``--where FIELD=V1,V2`` keeps the points with those values (repeat it for several fields)::

    python experiments/plot_curves.py fig5.csv --where initial_episodes=192 --out fig.png
"""

from __future__ import annotations

import argparse
import csv
import os
import textwrap
import warnings

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) stays

#: Columns of a sweep's CSV that name each row's value (``flrjax.config.SWEEP_FIELDS``).
SWEEP_COLUMNS = {"flr_alpha": "α", "flr_eps": "ε", "flr_next": "next",
                 "initial_episodes": "initial episodes", "pig_jump_temp": "jump_temp"}


def _path(run_dir: str) -> str:
    return run_dir if run_dir.endswith(".csv") else os.path.join(run_dir, "metrics.csv")


def _rows(run_dir: str) -> list[dict]:
    with open(_path(run_dir)) as f:
        return list(csv.DictReader(f))


def has_column(run_dir: str, name: str) -> bool:
    """Whether the run's CSV header has ``name`` (a metric only some methods log)."""
    with open(_path(run_dir), newline="") as f:
        return name in next(csv.reader(f), [])


def sweep_values(run_dir: str) -> list[dict[str, str]]:
    """The swept values of a run, one dict per sweep point in the run's order (``[{}]`` for a
    plain run)."""
    rows = _rows(run_dir)
    cols = [c for c in SWEEP_COLUMNS if rows and c in rows[0]]
    points = dict.fromkeys(tuple(r[c] for c in cols) for r in rows)
    return [dict(zip(cols, p, strict=True)) for p in points] or [{}]


def point_label(point: dict[str, str]) -> str:
    """``α=0.01 (FLR) ε=2``; α = 0 is the sparse reward of eq. (1), i.e. the base method."""
    def flr(k: str, v: str) -> str:
        return "" if k != "flr_alpha" else " (no FLR)" if float(v) == 0 else " (FLR)"

    return " ".join(f"{SWEEP_COLUMNS[k]}={v}{flr(k, v)}" for k, v in point.items())


def _where(text: str) -> tuple[str, set[str]]:
    field, eq, values = text.partition("=")
    if not eq or field not in SWEEP_COLUMNS:
        raise argparse.ArgumentTypeError(f"{text!r}: expected FIELD=V1[,V2...] with FIELD one "
                                         f"of {', '.join(SWEEP_COLUMNS)}")
    return field, set(values.split(","))


def _keep(point: dict[str, str], where: list[tuple[str, set[str]]]) -> bool:
    """Whether a sweep point has one of the wanted values of every ``--where`` field (values
    compared as numbers where they are numbers: 0.5 is 0.50)."""
    def same(a: str, b: str) -> bool:
        try:
            return float(a) == float(b)
        except ValueError:
            return a == b

    return all(field in point and any(same(point[field], v) for v in values)
               for field, values in where)


def curve(run_dir: str, metric: str, cumulative: bool = False, smooth: int = 1,
          where: dict[str, str] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(steps, mean, std over seeds) of ``metric`` in ``run_dir``/metrics.csv (or a CSV);
    ``cumulative`` sums it over evaluations per seed first (the paper's fall counts);
    ``smooth`` averages each seed over its last ``smooth`` evaluations first (the paper's
    curves are "smoothed equally", with no window given); ``where`` keeps the rows of one
    sweep point (:func:`sweep_values`)."""
    rows = [r for r in _rows(run_dir) if all(r[k] == v for k, v in (where or {}).items())]
    steps = np.array(sorted({int(r["step"]) for r in rows}))
    seeds = sorted({int(r["seed"]) for r in rows})
    table = np.full((len(steps), len(seeds)), np.nan)
    for r in rows:
        i, j = np.searchsorted(steps, int(r["step"])), seeds.index(int(r["seed"]))
        if not np.isnan(table[i, j]):  # rows of two sweep points would overwrite each other
            raise ValueError(f"{run_dir}: two rows for seed {r['seed']} at step {r['step']}; "
                             "a swept column missing from SWEEP_COLUMNS?")
        table[i, j] = float(r[metric])
    if cumulative:
        table = np.cumsum(table, axis=0)
    with warnings.catch_warnings():  # a window with no value stays NaN (a gap), silently
        warnings.simplefilter("ignore", RuntimeWarning)
        table = np.array([np.nanmean(table[max(0, i + 1 - smooth):i + 1], axis=0)
                          for i in range(len(table))])
    vals = list(table)
    with np.errstate(all="ignore"):  # a metric with no data at a step (NaN) stays a gap
        mean = np.array([np.nanmean(v) if np.isfinite(v).any() else np.nan for v in vals])
        std = np.array([np.nanstd(v) if np.isfinite(v).any() else np.nan for v in vals])
    return steps, mean, std


def curves_to_draw(runs: list[str], labels: list[str], metric: str,
                   where: list[tuple[str, set[str]]], keep_colors: bool = False,
                   ) -> list[tuple[str, str, dict[str, str], str]]:
    """``(run, label, sweep point, colour)`` of every curve, coloured C0, C1, ... in run and
    point order. With ``keep_colors`` a run whose CSV lacks ``metric`` is left out but keeps
    its colours, so the plots of one figure colour each run alike."""
    out, n = [], 0
    for run, label in zip(runs, labels, strict=True):
        points = [pt for pt in sweep_values(run) if _keep(pt, where)]
        if not points:
            raise ValueError(f"no sweep point of {run} matches --where")
        drawn = not keep_colors or has_column(run, metric)
        # label by what differs between the plotted points (all of it for a single one)
        same = {k for k in points[0] if len(points) > 1 and len({pt[k] for pt in points}) == 1}
        for point in points:
            shown = {k: v for k, v in point.items() if k not in same}
            if drawn:
                out.append((run, " ".join(filter(None, [label, point_label(shown)])), point,
                            f"C{n % 10}"))
            n += 1
    return out


def fit_title(fig: Figure, ax: Axes, title: str, fontsize: float = 9) -> None:
    """Set ``title``, wrapped at the longest line length that stays inside the figure after
    ``tight_layout`` (how many characters fit depends on which ones they are)."""
    for width in range(90, 20, -5):
        text = ax.set_title("\n".join(textwrap.fill(line, width) for line in title.splitlines()),
                            fontsize=fontsize)
        fig.tight_layout()
        box = text.get_window_extent()
        if box.x0 >= 0 and box.x1 <= fig.bbox.width:
            return


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="run directories holding metrics.csv, or CSVs")
    p.add_argument("--metric", default="success_rate")
    p.add_argument("--cumulative", action="store_true", help="sum over evaluations per seed")
    p.add_argument("--smooth", type=int, default=1,
                   help="average each seed over its last N evaluations (1: none)")
    p.add_argument("--labels", default=None, help="comma-separated labels, one per run")
    p.add_argument("--where", type=_where, action="append", default=[],
                   help="FIELD=V1[,V2...]: only the sweep points with these values")
    p.add_argument("--keep-colors", action="store_true",
                   help="skip runs without --metric but keep their colours for the others")
    p.add_argument("--title", default="")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if args.smooth < 1:
        p.error("--smooth must be at least 1")
    labels = args.labels.split(",") if args.labels else [os.path.basename(r).removesuffix(".csv")
                                                        for r in args.runs]
    try:
        planned = curves_to_draw(args.runs, labels, args.metric, args.where, args.keep_colors)
    except ValueError as e:
        p.error(str(e))
    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    for run, label, point, color in planned:
        x, m, s = curve(run, args.metric, args.cumulative, args.smooth, point)
        ax.plot(x, m, label=label, color=color)
        ax.fill_between(x, m - s, m + s, alpha=0.25, color=color)
    ax.set_xlabel("env steps per seed")
    ax.set_ylabel(("cumulative " if args.cumulative else "") + args.metric)
    title = args.title + (f" (smoothed over {args.smooth} evaluations)"
                          if args.smooth > 1 else "")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fit_title(fig, ax, title)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
