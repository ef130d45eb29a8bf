"""Score the points of a sweep by time to result: per sweep point, the wall-clock seconds and
env steps per seed until its seed-mean evaluation success first reaches ``--threshold``
(none where it never does), and its seed-mean success at fixed wall-clock ``--budgets``; for
the graph methods also the env steps until the landmarks first come within ``--gap`` of the
goal (the seed-mean ``goal_landmark_gap``: the onset of success waits for it, docs/results.md).

    python experiments/sweep_score.py RUN [RUN ...] --threshold 0.8 --budgets 300,600 \\
        --out results/lr_sweep/score

A RUN is a run directory (its metrics.csv) or a CSV of ``run_grid.py``: one program, whose
sweep points (``--lr-critic 3e-4,1e-3 --flr-alpha 0,0.01``, say) share its clock. Several runs
(programs of other shapes: batch sizes, envs per seed) are scored alike, each on its own
clock. Seconds are the trainer's ``wall_time`` (from its launch, compile included). Writes
``OUT.md`` (a table), ``OUT.json`` (every number) and ``OUT.png``: seconds to the threshold
for each point's setting (its swept values other than the method's own flags, less the base
values most of its run's points share, and the run where there are several), one colour per
method (an FLR run's α = 0 point is its base method, DHRL); points that never reach it are
drawn on the right edge.
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
from matplotlib.figure import Figure  # no pyplot: the caller's backend stays

from flrjax import algos
from flrjax.analysis import (
    field_label,
    format_steps,
    number,
    point_name,
    read_rows,
    run_record,
    select,
    sweep_values,
    value_text,
)
from flrjax.options import flags_of


def split_point(algo: str | None, point: dict[str, str]) -> tuple[str, dict[str, str]]:
    """A point's method (the paper's name with the swept flags that make it that method: those
    its base method lacks, e.g. FLR's ``FLR+DHRL α=0.01``; ``""`` where the run's config names
    no method) and its other swept values (learning rates, exploration, the graph's, ...)."""
    if algo is None or algo not in algos.names():
        return "", dict(point)
    m = algos.get(algo)
    own = (set(flags_of(m.options)) - set(flags_of(algos.get(m.base).options))
           if m.base else set())  # a method of no base is its name alone
    mine = {k: _typed(v) for k, v in point.items() if k in own}
    return point_name(algo, mine), {k: v for k, v in point.items() if k not in own}


def _fixed_method_values(algo: str | None, config: dict) -> dict[str, str]:
    """The run's one value of each flag that decides its method (:attr:`Method.base_point`,
    FLR's α) where that flag is not swept, so that a method is named alike whether its α is a
    sweep point or one flag (``FLR+DHRL α=0.01`` both ways)."""
    m = algos.get(algo) if algo in algos.names() else None
    return {k: str(config[k]) for k, _ in (m.base_point if m is not None else ())
            if config.get(k) is not None and not isinstance(config[k], list)}


def _typed(cell: str) -> float | str:
    """A CSV cell as the config holds it: a number where it is one ("0.0" is α = 0)."""
    try:
        return float(cell)
    except ValueError:
        return cell


def score_point(rows: list[dict], threshold: float, budgets: list[float],
                gap: float = 5.0, steps_planned: int | None = None) -> dict:
    """One point's rows (every seed, every evaluation): the first evaluation whose seed-mean
    success is at least ``threshold`` (``seconds``, ``env_steps``; None if none), the
    seed-mean success of the last evaluation within each budget (None before the first, and
    past the last where the run stopped short of ``steps_planned``, e.g. by a time limit), the
    number of seeds and the last step; with a ``goal_landmark_gap`` column, the first step
    whose seed-mean gap (over the seeds with a graph) is below ``gap`` (``landmarks_near_goal``;
    None if none)."""
    steps = sorted({int(r["step"]) for r in rows})
    mean, seconds, gaps = [], [], []
    for s in steps:
        at = [r for r in rows if int(r["step"]) == s]
        mean.append(float(np.mean([number(r["success_rate"]) for r in at])))
        seconds.append(max(number(r["wall_time"]) for r in at))
        g = [number(r["goal_landmark_gap"]) for r in at if r.get("goal_landmark_gap")]
        gaps.append(np.nanmean(g) if np.isfinite(g).any() else np.nan)
    first = next((i for i, m in enumerate(mean) if m >= threshold), None)
    near = next((s for s, g in zip(steps, gaps, strict=True) if g < gap), None)
    within = {b: [m for m, t in zip(mean, seconds, strict=True) if t <= b] for b in budgets}
    cut = steps_planned is not None and steps[-1] < steps_planned
    return {"seconds": None if first is None else seconds[first],
            "env_steps": None if first is None else steps[first],
            "at_budget": {str(b): (w[-1] if w and not (cut and b > seconds[-1]) else None)
                          for b, w in within.items()},
            "seeds": len({r["seed"] for r in rows}), "last_step": steps[-1],
            "last_seconds": seconds[-1],
            **({"landmarks_near_goal": near} if "goal_landmark_gap" in rows[0] else {})}


def run_names(runs: list[str]) -> list[str]:
    """Each run's name: its directory's or CSV's, with its folder where two names clash
    (``levers_1.44M/critic_atoms51`` beside ``levers_1.92M/critic_atoms51``)."""
    parts = [os.path.normpath(run).removesuffix(".csv").split(os.sep) for run in runs]
    names = [p[-1] for p in parts]
    return ["/".join(p[-2:]) if names.count(n) > 1 else n
            for p, n in zip(parts, names, strict=True)]


def score(runs: list[str], threshold: float, budgets: list[float],
          gap: float = 5.0) -> list[dict]:
    """Every sweep point of every run, scored (:func:`score_point`), with its run, method
    and setting."""
    out = []
    for run, name in zip(runs, run_names(runs), strict=True):
        rows = read_rows(run)
        config = run_record(run).get("config", {})
        algo = config.get("algo")
        fixed = _fixed_method_values(algo, config)
        for point in sweep_values(run):
            method, setting = split_point(algo, {**fixed, **point})
            out.append({"run": name, "method": method, "setting": setting,
                        **score_point(select(rows, list(point.items())), threshold, budgets,
                                      gap, config.get("steps"))})
    return out


def _shown(entry: dict, scores: list[dict]) -> dict:
    """The entry's setting without the values that most points of its run share (in a run of
    three or more points: a list sweep's base values), so a label names what the point
    changes."""
    mine = [s["setting"] for s in scores if s["run"] == entry["run"]]
    return {k: v for k, v in entry["setting"].items()
            if not (len(mine) > 2 and 2 * sum(m.get(k) == v for m in mine) > len(mine))}


def _setting_text(entry: dict, scores: list[dict]) -> str:
    parts = [f"{field_label(k)}={value_text(v)}" for k, v in _shown(entry, scores).items()]
    several_runs = len({s["run"] for s in scores}) > 1
    return " ".join(([entry["run"]] if several_runs or not parts else []) + parts)


def markdown(scores: list[dict], threshold: float, budgets: list[float],
             gap: float = 5.0) -> str:
    """The scores as a Markdown table, one row per point."""
    graph = any("landmarks_near_goal" in s for s in scores)
    head = ["method", "setting", "seeds", f"seconds to {threshold:g}", "env steps per seed",
            *(f"success at {b:g} s" for b in budgets),
            *([f"landmarks within {gap:g} of the goal (steps)"] if graph else []),
            "trained (steps, s)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in scores:
        reached = s["seconds"] is not None
        cells = [s["method"] or "-", _setting_text(s, scores) or "-", str(s["seeds"]),
                 f"{s['seconds']:.0f}" if reached else "not reached",
                 format_steps(s["env_steps"]) if reached else "-",
                 *("-" if v is None else f"{v:.2f}" for v in s["at_budget"].values()),
                 *([format_steps(s["landmarks_near_goal"]) if s.get("landmarks_near_goal")
                    else "-"] if graph else []),
                 f"{format_steps(s['last_step'])}, {s['last_seconds']:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(scores: list[dict], threshold: float, path: str, title: str = "") -> None:
    """Seconds to the threshold (x) for each setting (a row), one colour per method; a point
    never reaching it is an open marker on the right edge."""
    settings = list(dict.fromkeys(_setting_text(s, scores) for s in scores))
    reached = [s["seconds"] for s in scores if s["seconds"] is not None]
    right = 1.1 * max(reached + [s["last_seconds"] for s in scores])
    fig = Figure(figsize=(9.0, max(3.0, 0.26 * len(settings) + 1.4)))
    ax = fig.add_subplot()
    for i, method in enumerate(dict.fromkeys(s["method"] for s in scores)):
        mine = [s for s in scores if s["method"] == method]
        y = [settings.index(_setting_text(s, scores)) for s in mine]
        hit = [s["seconds"] is not None for s in mine]
        ax.plot([s["seconds"] for s, h in zip(mine, hit, strict=True) if h],
                [yi for yi, h in zip(y, hit, strict=True) if h], "o", color=f"C{i % 10}",
                label=method or "run")
        ax.plot([right] * hit.count(False), [yi for yi, h in zip(y, hit, strict=True) if not h],
                "o", mfc="none", color=f"C{i % 10}")
    ax.axvline(right, color="gray", ls=":", lw=1)
    ax.text(right, -0.9, "not reached ", ha="right", va="center", fontsize=7, color="gray")
    ax.set_yticks(range(len(settings)), settings, fontsize=7)
    ax.set_ylim(len(settings) - 0.5, -1.3)
    ax.set_xlim(0, right * 1.04)
    ax.grid(axis="x", alpha=0.3)
    ax.set_xlabel(f"seconds until seed-mean success ≥ {threshold:g} (each run's own clock)")
    ax.set_title(title or f"time to success {threshold:g} per sweep point", fontsize=10, pad=20)
    ax.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=4, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def _budgets(text: str) -> list[float]:
    try:
        values = [float(b) for b in text.split(",") if b.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not seconds: {text!r}") from None
    if any(not b > 0 for b in values):
        raise argparse.ArgumentTypeError(f"budgets must be positive seconds, got {text!r}")
    return values


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", help="run directories holding metrics.csv, or CSVs")
    p.add_argument("--threshold", type=float, default=0.8,
                   help="seed-mean success to reach (default 0.8)")
    p.add_argument("--budgets", type=_budgets, default=[],
                   help="wall-clock budgets in seconds, e.g. 300,600")
    p.add_argument("--gap", type=float, default=5.0,
                   help="landmarks this close to the goal (true path) count as there "
                        "(default 5: the mazes' success radius)")
    p.add_argument("--title", default="")
    p.add_argument("--out", required=True, help="OUT.md, OUT.json and OUT.png are written")
    args = p.parse_args(argv)
    if not 0 < args.threshold <= 1:
        p.error(f"--threshold is a success rate in (0, 1], got {args.threshold:g}")
    for run in args.runs:
        try:
            rows = read_rows(run)
        except OSError as e:
            p.error(f"{run}: {e.strerror or e}")
        if not rows or not {"step", "seed", "success_rate", "wall_time"} <= rows[0].keys():
            p.error(f"{run}: no metrics rows with step, seed, success_rate and wall_time")
    if not args.gap > 0:
        p.error(f"--gap is a distance > 0, got {args.gap:g}")
    scores = score(args.runs, args.threshold, args.budgets, args.gap)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out + ".md", "w") as f:
        f.write(markdown(scores, args.threshold, args.budgets, args.gap))
    with open(args.out + ".json", "w") as f:
        json.dump({"runs": args.runs, "threshold": args.threshold, "budgets": args.budgets,
                   "gap": args.gap, "points": scores}, f, indent=1)
    plot(scores, args.threshold, args.out + ".png", args.title)
    print(markdown(scores, args.threshold, args.budgets, args.gap), end="")
    return scores


if __name__ == "__main__":
    main()
