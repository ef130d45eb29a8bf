"""One command per figure of the paper: runs its grid of methods and settings, plots it.

    python experiments/figures.py fig2 --out experiments/results/fig2
    python experiments/figures.py fig4 --time-limit 540 --out experiments/results/fig4

Each figure's runs go through ``run_grid.py`` (seeds vmapped): ``OUT/<run>.csv`` and
``OUT/grid.json`` (configs, wall times, device). On a host with several GPUs the runs go side
by side, one per GPU (``--gpus 0,1`` to choose them; a run's output in
``RUNS/logs/<run>.log``), else one after the other; on a SLURM cluster each run is a job
through submitit (``pip install 'flrjax[cluster]'``)::

    python experiments/figures.py fig5 --out experiments/results/fig5 --submitit slurm \\
        --slurm-partition gpu --time-limit 14000

A figure's settings are sweep points of vmapped runs, DHRL being the α = 0 point of an
FLR+DHRL run (eq. 5 with α = 0 is eq. 1): Figs. 3 and 5 are Fig. 2's DHRL / FLR+DHRL run and
two more of 10 runs each, so that each run fits a shorter job. The plots go to
``OUT/<figure>[_<panel>]_<metric>.png``, a panel plotting some of the runs: mean ± sample std
over seeds (the band clipped to the metric's range), smoothed over the last ``--smooth``
evaluations (5; cumulative falls not), every curve cut at the last step all of the plot's curves
reach (``--full-steps``: not), the paper's names of the methods and envs, axes in words, and the
devices in the title. A metric no run has a value of is not plotted, nor are the falls and torso
height of the point mass (which cannot fall). The defaults are the fast protocol our GPU runs
use: 5 seeds x 16 envs, 0.25 updates per env step, 192 random initial episodes; ``--steps``,
``--seeds``, ``--env`` and ``--extra`` (more trainer flags) change them. A figure's full grid
may take longer than one job may run: ``--only`` runs a subset, and ``--time-limit`` stops
cleanly so that the same command, run again, continues. A failed run is reported, and the
figure plots the others before it exits with an error. ``--take
DIR/RUN`` copies a finished run of another figure's ``--out`` into this one, e.g. Fig. 3's DHRL
/ FLR+DHRL run as Fig. 5's control.
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import launch  # noqa: E402
import merge_seeds  # noqa: E402
import plot_curves  # noqa: E402
import run_grid  # noqa: E402

from flrjax.analysis import (  # noqa: E402
    FALL_METRICS,
    can_fall,
    env_name,
    format_steps,
    has_data,
    plural,
)
from flrjax.options import int_value  # noqa: E402

#: DHRL and PIG, each as the alpha 0 point of one vmapped run with its FLR version: Fig. 2's
#: runs, which Fig. 4 replots (one list, so that the two figures' runs stay the same runs).
BASE_VS_FLR = [("dhrl", "--algo flr_dhrl --flr-alpha 0,0.01"),
               ("pig", "--algo flr_pig --flr-alpha 0,0.01")]

#: Fig. 2 right (ant4leg): the paper adds FLR to PIG on the tripod only, so here PIG runs alone
#: (5 runs, not 10: more steps per device minute, and the paper's PIG surges after 1M).
FIG2_ANT4LEG = [BASE_VS_FLR[0], ("pig", "--algo pig"), ("higl", "--algo higl")]

#: Fig. 5's points besides Fig. 2's DHRL / FLR+DHRL run (alpha 0 / 0.01 at eps 2): alpha 0.001
#: and 0.1 (Fig. 5c), and eps 0.5 = delta and the final goal as the next subgoal (Fig. 5a-b),
#: each at alpha 0.01. Three runs of 10 (not one of 30), so that each fits a shorter job.
FIG5_RUNS = [("flr_dhrl_alpha", "--algo flr_dhrl --flr-alpha 0.001,0.1"),
             ("flr_dhrl_next", "--algo flr_dhrl --sweep 'flr-eps=0.5; flr-next=goal'")]

#: The trainer flags of every figure run: the ``fast`` protocol, whichever preset is the default.
EXTRA = "--preset fast"

#: Fig. 3's burn-ins besides Fig. 2's DHRL / FLR+DHRL run (the fast preset's 192 initial
#: random episodes): 48 and 96, each DHRL (alpha 0) and FLR+DHRL, a run of 10 (one job).
FIG3_RUNS = [(f"initial_{n}", f"--algo flr_dhrl --flr-alpha 0,0.01 --initial-episodes {n}")
             for n in (48, 96)]

#: Evaluations each seed's curve is averaged over (a trailing mean; the paper's curves are
#: "smoothed equally", with no window given): 5 evaluations are 240k env steps at the fast
#: protocol (an evaluation every 48k); a run of fewer evaluations is smoothed over all it has,
#: which the title says. Cumulative falls are not smoothed (a sum is smooth, and a trailing
#: mean of it would understate the count at each step).
SMOOTH = 5

#: figure -> how its legend names a run: a format string over the run's config in grid.json
#: (Fig. 3's runs differ in a plain flag, which no CSV column shows).
LEGENDS = {"fig3": "{initial_episodes} initial episodes"}

#: How a title names a figure's panel (the paper's Fig. 5a-b and 5c).
PANEL_NAMES = {"next": "the next subgoal", "alpha": "α"}

#: figure -> (default env, [(run name, trainer flags)], metrics to plot, {panel: the runs it
#: plots}; panel "" with no runs named plots all of them). Paper §3.
FIGURES: dict[str, tuple[str, list[tuple[str, str]], tuple[str, ...],
                         dict[str, tuple[str, ...]]]] = {
    # Fig. 2: success rate of every method (the paper shows FLR+PIG on ant3leg only), and
    # PIG's policy alone, without its planner (which of the two the paper plots is open).
    "fig2": ("ant3leg", [*BASE_VS_FLR, ("higl", "--algo higl")],
             ("success_rate", "no_plan_success_rate"), {"": ()}),
    # Fig. 3: robustness to the number of initial random episodes: DHRL (alpha 0) and
    # FLR+DHRL after 192 (Fig. 2's run), 96 and 48.
    "fig3": ("ant3leg", [BASE_VS_FLR[0], *FIG3_RUNS],
             ("success_rate", "final_goal_distance", "falls"), {"": ()}),
    # Fig. 4: falls, final torso height and the FLR reward gap, upright - fallen, of Fig. 2's
    # DHRL and PIG runs (with Fig. 2's --out it only replots them).
    "fig4": ("ant3leg", BASE_VS_FLR, ("falls", "final_torso_z", "reward_gap"), {"": ()}),
    # Fig. 5: the next-subgoal choice (eps 2, eps 0.5 = delta, the final goal; Fig. 5a-b) and
    # alpha (Fig. 5c), each against DHRL: Fig. 2's run and FIG5_RUNS.
    "fig5": ("ant3leg", [BASE_VS_FLR[0], *FIG5_RUNS], ("success_rate", "falls", "reward_gap"),
             {"next": ("dhrl", "flr_dhrl_next"), "alpha": ("dhrl", "flr_dhrl_alpha")}),
}


def _title(figure: str, env: str, out: str, names: list[str], cut: bool = False,
           panel: str = "") -> str:
    """``Fig. 5 (α), AntMaze3Leg, 5 seeds`` (the paper's names: :data:`PANEL_NAMES`,
    ``analysis.ENV_NAMES``) over ``0.62M env steps per seed (time-limited; 1.92M
    planned)``: what the plotted runs of ``out``/grid.json reached (each run's own steps where
    they differ; "time-limited" where one stopped short of its own steps). With ``cut`` (the
    curves cut at the step all of them reach, which ``plot_curves.py`` states) only whether
    some run was time-limited. The devices are ``plot_curves.py``'s to list."""
    name = f"Fig. {figure.removeprefix('fig')}" + (f" ({PANEL_NAMES.get(panel, panel)})"
                                                   if panel else "")
    recs = {n: r for n, r in run_grid.records(out).items() if n in names}
    if not recs:
        return f"{name}, {env_name(env)}"
    done = {n: r["steps_done"] for n, r in recs.items()}
    planned = max(r["config"]["steps"] for r in recs.values())
    limited = any(r["steps_done"] < r["config"]["steps"] for r in recs.values())
    seeds = sorted({r["config"]["seeds"] for r in recs.values()})
    count = plural(seeds[0], "seed") if len(seeds) == 1 else (
        "/".join(map(str, seeds)) + " seeds")
    head = f"{name}, {env_name(env)}, {count}"
    fmt = format_steps
    if cut:
        return head + (f", time-limited runs ({fmt(planned)} steps planned)" if limited else "")
    steps = (fmt(min(done.values())) if len(set(done.values())) == 1 else
             ", ".join(f"{n} {fmt(s)}" for n, s in done.items()))
    return (f"{head}\n{steps} env steps per seed"
            + (f" (time-limited; {fmt(planned)} planned)" if limited else ""))


def _legend(figure: str, out: str, name: str) -> str:
    """Run ``name``'s legend label: :data:`LEGENDS`' format over its grid.json config, or its
    name (also when it has no record)."""
    rec = run_grid.records(out).get(name)
    return LEGENDS[figure].format(**rec["config"]) if figure in LEGENDS and rec else name


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("figure", choices=sorted(FIGURES))
    p.add_argument("--out", required=True)
    p.add_argument("--env", default=None, help="default: the figure's env")
    p.add_argument("--seeds", type=int_value, default=5)
    p.add_argument("--steps", type=int_value, default=1_920_000,
                   help="env steps per seed (default: the fast preset's budget)")
    p.add_argument("--extra", default=EXTRA,
                   help="trainer flags for every run (a run's own flags come after)")
    p.add_argument("--only", default=None, help="comma-separated run names to run")
    p.add_argument("--plot-only", action="store_true", help="replot the CSVs in --out")
    p.add_argument("--time-limit", default=None, metavar="SECONDS",
                   help="stop cleanly before SECONDS; the same command again continues "
                        "(run_grid.py)")
    p.add_argument("--smooth", type=int_value, default=SMOOTH,
                   help=f"average each seed's curve over its last N evaluations (default "
                        f"{SMOOTH}); cumulative falls are not smoothed")
    p.add_argument("--full-steps", action="store_true",
                   help="plot each curve to its own last step (default: all curves of a plot "
                        "cut at the last step all of them reach)")
    p.add_argument("--runs", default=None,
                   help="run directories with checkpoints (run_grid.py's default if unset)")
    p.add_argument("--adopt", default=None, metavar="DIR,DIR,...",
                   help="with --only RUN: finished standalone runs to take as RUN's sweep "
                        "points instead of training it (run_grid.py)")
    p.add_argument("--take", default=None, metavar="DIR/RUN,...",
                   help="runs of another figure's --out to copy into --out first (CSV and "
                        "grid.json record), e.g. a control two figures share")
    launch.add_arguments(p)
    args = p.parse_args(argv)
    for part in args.take.split(",") if args.take else ():
        merge_seeds.adopt(args.out, part)
    env, runs, metrics, panels = FIGURES[args.figure]
    env = args.env or env
    if args.figure == "fig2" and env == "ant4leg":
        runs = FIG2_ANT4LEG
    if args.only:
        keep = set(args.only.split(","))
        runs = [r for r in runs if r[0] in keep]
    if args.adopt and len(runs) != 1:
        p.error("--adopt needs --only with one run")
    failed = None
    if not args.plot_only:
        base = f"--env {env} --seeds {args.seeds} --steps {args.steps} {args.extra}"
        try:
            run_grid.main(["--out", args.out, "--base", base,
                           *(["--time-limit", args.time_limit] if args.time_limit else []),
                           *(["--runs", args.runs] if args.runs else []),
                           *(["--adopt", args.adopt] if args.adopt else []),
                           *launch.forward(args),
                           *(f"{name}={flags}" for name, flags in runs)])
        except launch.Failed as e:  # the others ran: plot them, then fail
            failed = e
    done = [name for name, _ in FIGURES[args.figure][1]
            if os.path.exists(os.path.join(args.out, f"{name}.csv"))]
    for metric in metrics if can_fall(env) else [m for m in metrics if m not in FALL_METRICS]:
        have = [n for n in done
                if has_data(os.path.join(args.out, f"{n}.csv"), metric)]
        for panel, names in panels.items() if have else ():
            shown = [n for n in done if n in names or not names]
            if not any(n in have for n in shown) or len(shown) < len(names):
                continue  # a panel of named runs waits for all of them
            name = "_".join(filter(None, (args.figure, panel, metric)))
            plot_curves.main([*(os.path.join(args.out, f"{n}.csv") for n in shown),
                              "--labels", ",".join(_legend(args.figure, args.out, n)
                                                   for n in shown),
                              "--metric", metric, "--title", _title(
                                  args.figure, env, args.out, [n for n in have if n in shown],
                                  cut=not args.full_steps, panel=panel),
                              "--keep-colors", *([] if args.full_steps else ["--common-steps"]),
                              *(["--cumulative"] if metric == "falls" else
                                ["--smooth", str(args.smooth)]),
                              "--out", os.path.join(args.out, f"{name}.png")])
    if failed:
        raise failed


if __name__ == "__main__":
    main()
