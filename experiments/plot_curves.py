"""Plot a metric of one or more runs against env steps: mean ± sample std over seeds.

    python experiments/plot_curves.py RUN_DIR [RUN_DIR ...] --metric success_rate --out fig.png

A run that swept ``--flr-alpha``, ``--flr-eps``, ``--flr-next``, ``--initial-episodes`` or
``--pig-jump-temp`` (a column of that name in its CSV) gives one curve per sweep point, in the
run's order;
``--where FIELD=V1,V2`` keeps the points with those values (repeat it for several fields)::

    python experiments/plot_curves.py fig5.csv --where initial_episodes=192 --out fig.png

The legend names each curve as the paper does (DHRL, FLR+DHRL, PIG, FLR+PIG, HIGL: an FLR run's
α = 0 point is its base method), with the settings that differ between the plot's curves
(α, ε, the final goal as the next subgoal, the initial episodes), where the run's config says
its method: its ``config.json`` (a run directory) or its record in the ``grid.json`` beside
``NAME.csv`` (``run_grid.py``); other runs keep ``--labels``. The band is ± the sample
standard deviation over seeds (ddof 1), clipped to the metric's range ([0, 1] for success
rates and fractions, >= 0 for counts and distances); the y axis names the metric in words with
its unit. A curve with no value (a metric never measured, e.g. the reward gap of a body that
never falls) is left out. ``--common-steps`` cuts every curve at the last step all of them
reach; the title lists the runs' devices, the cut (where it shortens a curve) and the
smoothing window (at most the evaluations a curve has).
"""

from __future__ import annotations

import argparse
import os
import textwrap

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) stays
from matplotlib.ticker import FuncFormatter

from flrjax import algos
from flrjax.analysis import (
    curve,
    device_name,
    field_label,
    format_steps,
    has_column,
    known_method,
    metric_label,
    metric_range,
    run_record,
    same,
    seeds,
    sweep_values,
    value_text,
)
from flrjax.config import sweep_fields
from flrjax.options import flags_of


def point_label(point: dict[str, str]) -> str:
    """``α=0.01 (FLR) ε=2``; α = 0 is the sparse reward of eq. (1), i.e. the base method."""
    def flr(k: str, v: str) -> str:
        return "" if k != "flr_alpha" else " (no FLR)" if float(v) == 0 else " (FLR)"

    return " ".join(f"{field_label(k)}={value_text(v)}{flr(k, v)}" for k, v in point.items())


def _range_text(lo: float, hi: float) -> str:
    return ("" if lo == -np.inf and hi == np.inf else f"[{lo:g}, {hi:g}]" if hi < np.inf
            else f">= {lo:g}" if lo > -np.inf else f"<= {hi:g}")




def _number(v: object) -> object:
    try:
        return float(v)  # "0.0" and 0 alike
    except (TypeError, ValueError):
        return v


def point_settings(info: dict, point: dict[str, str]) -> dict | None:
    """A sweep point's method (``algo``) and sweepable settings: the CSV's columns
    (``point``), else the run's config (an unset field at the trainer's default; a
    field the config lacks or sweeps is None, unknown); None when the config (:func:`run_info`)
    names no registered method."""
    config = info.get("config") or {}
    if not known_method(config.get("algo")):
        return None
    out = {"algo": config["algo"]}
    for k, f in sweep_fields().items():
        if k in point:
            v = point[k]
        elif k not in config or isinstance(config[k], list):
            v = None
        else:
            v = f.default if config[k] is None else config[k]
        out[k] = None if v is None else _number(v)
    return out


def _method(s: dict) -> algos.Method:
    """The method a curve's settings amount to (FLR at α = 0: its base method)."""
    return algos.point_method(s["algo"], {k: v for k, v in s.items() if v is not None})


def _applies(field: str, s: dict) -> bool:
    """Whether a setting means anything for the curve's method (:func:`_method`: FLR's
    settings not at α = 0, the base method), ε only where the next subgoal is sampled (not the
    final goal); the shared learners' numbers and the initial episodes always."""
    method = _method(s)
    return (field in flags_of(method.options) or field not in all_method_flags()) and not (
        field == "flr_eps" and s.get("flr_next") == "goal")


def all_method_flags() -> set[str]:
    """The flags some method owns (the others are every run's)."""
    return {k for m in algos.methods() for k in flags_of(m.options)}


def _setting(field: str, v: object) -> str:
    num = f"{v:g}" if isinstance(v, float) else str(v)
    if field == "flr_next":
        return "next = final goal" if v == "goal" else "" if v == "sample" else f"next = {v}"
    if field == "initial_episodes":
        return f"{num} initial episodes"
    return f"{field_label(field)}={num}"


def paper_names(settings: list[dict | None]) -> list[str | None]:
    """Each curve's name as the paper gives it (:func:`point_settings` of the plot's curves):
    DHRL / PIG for an FLR run's α = 0 point, FLR+DHRL / FLR+PIG for α > 0, then each setting
    that applies to it (:func:`_applies`) and differs between the curves it applies to, e.g.
    ``FLR+DHRL, α=0.001``, ``FLR+DHRL, ε=0.5``, ``FLR+DHRL, next = final goal``, ``DHRL, 48
    initial episodes``; None for a curve with no settings."""
    known = [s for s in settings if s]
    fields = sweep_fields()
    differ = {k for k in fields
              if len({s[k] for s in known if _applies(k, s) and s[k] is not None}) > 1}
    names: list[str | None] = []
    for s in settings:
        if s is None:
            names.append(None)
            continue
        shown = [_setting(k, s[k]) for k in fields
                 if k in differ and _applies(k, s) and s[k] is not None]
        names.append(", ".join([_method(s).paper_name, *filter(None, shown)]))
    return names


def _where(text: str) -> tuple[str, set[str]]:
    field, eq, values = text.partition("=")
    if not eq or field not in sweep_fields():
        raise argparse.ArgumentTypeError(f"{text!r}: expected FIELD=V1[,V2...] with FIELD one "
                                         f"of {', '.join(sweep_fields())}")
    return field, set(values.split(","))


def _keep(point: dict[str, str], where: list[tuple[str, set[str]]]) -> bool:
    """Whether a sweep point has one of the wanted values of every ``--where`` field (values
    compared as numbers where they are numbers: 0.5 is 0.50)."""
    return all(field in point and any(same(point[field], v) for v in values)
               for field, values in where)


def curves_to_draw(runs: list[str], labels: list[str], metric: str,
                   where: list[tuple[str, set[str]]], keep_colors: bool = False,
                   paper: bool = True) -> list[tuple[str, str, dict[str, str], str]]:
    """``(run, label, sweep point, colour)`` of every curve, coloured C0, C1, ... in run and
    point order. With ``keep_colors`` a run whose CSV lacks ``metric`` is left out but keeps
    its colours, so the plots of one figure colour each run alike. With ``paper`` a curve
    whose run's config names its method is labelled as the paper names it
    (:func:`paper_names`, over all the curves, drawn or not); the others (or all, without
    ``paper``) by their run's label and what differs between its sweep points."""
    out, n = [], 0
    planned = []
    for run, label in zip(runs, labels, strict=True):
        points = [pt for pt in sweep_values(run) if _keep(pt, where)]
        if not points:
            raise ValueError(f"no sweep point of {run} matches --where")
        # label by what differs between the plotted points (all of it for a single one)
        fixed = {k for k in points[0] if len(points) > 1 and len({pt[k] for pt in points}) == 1}
        info = run_record(run) if paper else {}
        for point in points:
            shown = {k: v for k, v in point.items() if k not in fixed}
            planned.append((run, " ".join(filter(None, [label, point_label(shown)])), point,
                            point_settings(info, point)))
    names = paper_names([settings for *_, settings in planned])
    for (run, label, point, _), name in zip(planned, names, strict=True):
        if not keep_colors or has_column(run, metric):
            out.append((run, name or label, point, f"C{n % 10}"))
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
        if box.x0 >= 10 and box.x1 <= fig.bbox.width - 10:  # a margin: no letter at the edge
            return


def _spacing(steps: np.ndarray) -> int | None:
    """The usual number of env steps between two evaluations."""
    if len(steps) < 2:
        return None
    gaps, counts = np.unique(np.diff(steps), return_counts=True)
    return int(gaps[counts.argmax()])


def smoothing_text(smooth: int, spacing: int | None, evaluations: int | None = None) -> str:
    """``smoothed over the last 5 evaluations (0.24M env steps)``, or ``not smoothed``: the
    window a plot of at most ``evaluations`` points per curve has, ``smooth`` or fewer."""
    window = smooth if evaluations is None else min(smooth, evaluations)
    if window <= 1:
        return "not smoothed"
    span = f" ({format_steps(window * spacing)} env steps)" if spacing else ""
    return f"smoothed over the last {window} evaluations{span}"


def devices_text(runs: list[str]) -> str:
    """``devices: H100, H200`` (or ``device: H200``): the devices the runs' configs name, a
    run merged from parts on several (``merge_seeds.py``: ``A / B``) naming each."""
    names = sorted({device_name(part) for d in (run_record(r).get("device") for r in runs) if d
                    for part in d.split(" / ")})
    return f"device{'s' if len(names) > 1 else ''}: {', '.join(names)}" if names else ""


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="run directories holding metrics.csv, or CSVs")
    p.add_argument("--metric", default="success_rate")
    p.add_argument("--cumulative", action="store_true", help="sum over evaluations per seed")
    p.add_argument("--smooth", type=int, default=1,
                   help="average each seed over its last N evaluations (1: none)")
    p.add_argument("--labels", default=None, help="comma-separated labels, one per run (for "
                   "the runs whose config does not name their method, or all with --legend "
                   "labels)")
    p.add_argument("--legend", choices=("paper", "labels"), default="paper",
                   help="paper: the paper's method names where a run's config (config.json, "
                        "or grid.json beside NAME.csv) names its method (default)")
    p.add_argument("--where", type=_where, action="append", default=[],
                   help="FIELD=V1[,V2...]: only the sweep points with these values")
    p.add_argument("--keep-colors", action="store_true",
                   help="skip runs without --metric but keep their colours for the others")
    p.add_argument("--common-steps", action="store_true",
                   help="cut every curve at the last step all of them reach")
    p.add_argument("--title", default="")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if args.smooth < 1:
        p.error("--smooth must be at least 1")
    labels = args.labels.split(",") if args.labels else [os.path.basename(r).removesuffix(".csv")
                                                        for r in args.runs]
    try:
        planned = curves_to_draw(args.runs, labels, args.metric, args.where, args.keep_colors,
                                 paper=args.legend == "paper")
    except ValueError as e:
        p.error(str(e))
    drawn = [(label, color, *curve(run, args.metric, args.cumulative, args.smooth, point))
             for run, label, point, color in planned]
    has = [np.isfinite(d[3]).any() for d in drawn]  # a curve with no data: no legend entry
    drawn = [d for d, h in zip(drawn, has, strict=True) if h]
    planned = [c for c, h in zip(planned, has, strict=True) if h]
    if not drawn:
        p.error(f"no run has a value of {args.metric}")
    ends = [x[-1] for _, _, x, _, _ in drawn]
    cut = min(ends) if args.common_steps else max(ends)
    lo, hi = metric_range(args.metric, args.cumulative)
    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.subplots()
    for label, color, x, m, s in drawn:
        keep = x <= cut
        x, m, s = x[keep], m[keep], s[keep]
        ax.plot(x, m, label=label, color=color)
        ax.fill_between(x, np.clip(m - s, lo, hi), np.clip(m + s, lo, hi), alpha=0.25,
                        color=color)
    ax.set_xlabel("env steps per seed")
    if cut >= 100_000:
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1e6:g}M" if v else "0"))
    n = sorted({seeds(run, point) for run, _, point, _ in planned})
    clipped = _range_text(lo, hi)
    spread = ("1 seed" if n == [1] else
              f"mean ± sample std over {n[0]}–{n[-1]} seeds" if len(n) > 1 else
              f"mean ± sample std over {n[0]} seeds")
    spread += f", band clipped to {clipped}" if clipped and n != [1] else ""
    ax.set_ylabel("\n".join(textwrap.fill(line, 56) for line in (
        metric_label(args.metric, args.cumulative), spread)), fontsize=9)
    evaluations = max(int((x <= cut).sum()) for _, _, x, _, _ in drawn)
    facts = [devices_text([run for run, *_ in planned]),
             f"cut at {format_steps(cut)} env steps per seed, the last step all curves reach"
             if cut < max(ends) else "",
             smoothing_text(args.smooth, _spacing(drawn[0][2]), evaluations)]
    title = "\n".join(filter(None, [args.title, "; ".join(filter(None, facts))]))
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fit_title(fig, ax, title)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
