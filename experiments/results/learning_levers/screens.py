"""The learning-lever screens of docs/results.md ("What the onset of success waits for"), each
program one flag's values × DHRL (α = 0) and FLR+DHRL (α = 0.01) × 3 seeds; writes beside each
folder's CSVs:

- ``screens_0.58M/screens.{txt,png}``: the seed-mean gap from the goal to its nearest landmark
  (``goal_landmark_gap``, m) at 0.288–0.576M env steps; both methods' 6 runs of each value at
  0.576M against the same program's default, and against the default of all four programs (the
  same flags and seeds);
- ``screens_1.44M/screens.{txt,png}``: each run's mean success over its last 5 evaluations
  (1.248–1.44M) per method, each value against its program's default, and the default's two
  programs (the same flags and seeds) against each other; the curves of success and of the gap;
- ``levers_1.44M/levers.{txt,png}``: the same reading of one program per opt-in lever
  (``--n-step 3``, ``--critic-atoms 51``, ``--critic-layer-norm``: DHRL and FLR+DHRL × 3 seeds)
  and of the batch-4,096 shape's learning rates, each against the default points of the two
  1.44M screens (the same flags and seeds without the lever); FLR+DHRL against DHRL in each
  program; the seed-mean mean Q of the main critics and their loss;
- ``levers_1.92M/levers.{txt,png}``: C51 and LayerNorm on 5 fresh seeds, and 64 / 128 envs per
  seed, to 1.92M (256 envs to 1.536M), each method against Fig. 2 left's runs over the same
  evaluations, FLR+DHRL against DHRL in each program; the curves in env steps and in the
  program's seconds;
- ``levers_1.92M/shapes.{txt,png}``: batch 2,048 / 4,096 and 512-wide hidden layers at the
  same 0.25 updates per env step (batch 4,096: FLR+DHRL alone) against ``envs128``'s batch
  1,024 over the same evaluations;
- ``wide_preset/preset.{txt,png}``: the ``wide`` preset (128 envs per seed) on 5 fresh seeds,
  DHRL beside FLR+DHRL in one program, to 1.92M, and with batch 2,048 on 5 other fresh seeds
  (stopped at 1.459M), read as ``levers_1.92M/``; ``batch2048.{txt,png}``: the two programs
  against each other over the same evaluations;
- ``learner_numbers/screens.{txt,png}``: the learner's numbers (Polyak, target noise, both
  levels' learning rates), FLR+DHRL alone in two list sweeps of the ``wide`` shape, each point
  against its program's reference point; the curves of success and of the low level's mean Q;
- ``learner_numbers/polyak_alpha.{txt,png}``: Polyak 0.995 / 0.99 (0.98) × α 0 / 0.005 / 0.01
  in one list sweep of the ``wide`` shape, lost at 1.152M; each rate against 0.995 at the same
  α, and FLR+DHRL against DHRL at each rate; the curves of success and of the gap from the goal
  to its nearest landmark; ``polyak5.{txt,png}``: the same reading of Polyak 0.995 / 0.99 ×
  α 0 / 0.01 on 5 fresh seeds to 1.536M;
- ``learner_numbers/her_periods.{txt,png}``: the low level's HER relabel ratio (one list
  sweep), the subgoal period and the target networks' period (a program per value), FLR+DHRL
  alone, each against the sweep's reference point; ``target_period5_5seeds.{txt,png}``: the
  target period 5 on the ``wide`` preset's 5 fresh seeds, DHRL beside, against that preset's
  program; ``obs_norm_5seeds``, ``obs_norm_period5_5seeds``: ``--obs-norm`` alone and with the
  target period 5 read alike; ``obs_norm_period5_fresh``: the latter on 5 other fresh seeds;
- ``tuned_preset/tuned.{txt,png}``: the ``tuned`` preset as run: the main command on one and
  on two H200s, and ``benchmarks/time_to_result.py`` on one H200 on each maze, against the
  same flags and seeds on 2 H200s; ``graph_start.{txt,png}``: the main command with its first
  graph after one random round against the main command as written, two seed sets;
- ``lever_cost/cost.txt``: seconds per chunk of ``--n-step 3`` and ``--critic-atoms 51``
  against the reference's critic, and the main critics' mean Q;
- ``chunk_cost.{txt,png}``: seconds per chunk of the ``wide`` shape's programs against the
  runs they vmap, a line fitted to those of batch 1,024, and the larger batches beside;
- ``onset_updates.{txt,png}``: each seed's first success in env steps and in low-level updates
  per run, over the programs of 0.0625 to 1 update per env step (a program without one: the
  updates it stopped at).

p: the difference of means, permuted (``experiments/claims.py``; exact for 3 against 3 seeds,
so never below 0.1 there)::

    PYTHONPATH=. python experiments/results/learning_levers/screens.py
"""
import json
import os
import warnings

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from experiments.claims import permutation_test
from flrjax.analysis import field_label, read_rows, run_record, same, seed_table, select, value_text

HERE = os.path.dirname(os.path.abspath(__file__))
ALPHAS = {"0.0": "DHRL", "0.01": "FLR+DHRL"}
SCREENS = {  # folder: {CSV: (swept column, its default)}
    "screens_0.58M": {"subgoal_noise": ("subgoal_noise_eps", "2.0"),
                      "random_eps": ("random_eps", "0.2"),
                      "noise_eps": ("noise_eps", "0.1"),
                      "lr_critic": ("lr_critic", "0.001")},
    "screens_1.44M": {"random_eps": ("random_eps", "0.2"),
                      "landmark_eps": ("landmark_eps", "10.0")},
}
GAP_STEPS = (288000, 384000, 480000, 576000)
LAST = 5


def curve(rows: list, field: str, value: str, alpha: str, metric: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """(steps, ``[steps, seeds]`` values) of one sweep point's metric."""
    steps, _, v = seed_table(select(rows, [(field, value), ("flr_alpha", alpha)]), metric)
    return steps, v


def seed_mean(v: np.ndarray) -> np.ndarray:
    """The mean over seeds per step; NaN before the first graph (no landmarks yet)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(v, axis=1)


def programs(folder: str) -> dict:
    """{program: (field, default, rows, values)} of one screen folder."""
    out = {}
    for name, (field, default) in SCREENS[folder].items():
        rows = read_rows(os.path.join(HERE, folder, f"{name}.csv"))
        out[name] = (field, default, rows, sorted({r[field] for r in rows}, key=float))
    return out


def gap_screen() -> list[str]:
    """The 0.58M screens, read by the landmarks' gap to the goal."""
    folder = "screens_0.58M"
    at = " / ".join(f"{s / 1e6:.3f}M" for s in GAP_STEPS)
    lines = [f"seed-mean goal_landmark_gap (m) at {at}"
             + "; pooled: both methods' 6 runs at 0.576M, mean ± sample std; p: the difference"
             " of means, permuted (experiments/claims.py)", ""]
    progs = programs(folder)
    fig = Figure(figsize=(13, 3.2))
    axes = fig.subplots(1, len(progs), sharey=True)
    defaults, pooled_values = [], {}
    for ax, (name, (field, default, rows, values)) in zip(axes, progs.items(), strict=True):
        last = {}
        for value in values:
            pooled = []
            for alpha, method in ALPHAS.items():
                steps, v = curve(rows, field, value, alpha, "goal_landmark_gap")
                mean = seed_mean(v)
                at = [mean[list(steps).index(s)] for s in GAP_STEPS]
                pooled.append(v[list(steps).index(GAP_STEPS[-1])])
                lines.append(f"{name:>13} {field}={value:<6} α={alpha:<4} "
                             + " ".join(f"{g:5.1f}" for g in at))
                ax.plot(steps / 1e6, mean, ls="-" if alpha == "0.0" else "--",
                        color=f"C{values.index(value)}", label=f"{value} {method}")
            last[value] = np.concatenate(pooled)
        defaults.append(last[default])
        pooled_values[name] = last
        ax.set_title(f"{field} (default {default})", fontsize=9)
        ax.set_xlabel("env steps per seed (M)")
        ax.axhline(5.0, color="gray", lw=0.5)
        ax.legend(fontsize=6)
    axes[0].set_ylabel("goal to nearest landmark (m)")
    every = np.concatenate(defaults)
    for (name, (field, default, _, _)), d in zip(progs.items(), defaults, strict=True):
        for value, x in pooled_values[name].items():
            p = ("" if value == default else f", p = {permutation_test(x, d):.3f} against the "
                 f"program's default, {permutation_test(x, every):.3f} against all four's")
            lines.append(f"{name:>13} {field}={value:<6} pooled {x.mean():5.1f} ± "
                         f"{x.std(ddof=1):.1f}{p}")
    means = [d.mean() for d in defaults]
    lines += ["", "the default in the four programs (same flags and seeds): pooled means "
              + " / ".join(f"{m:.1f}" for m in means)
              + f", range {max(means) - min(means):.1f} m"]
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, folder, "screens.png"), dpi=110)
    return lines


def success_screen() -> list[str]:
    """The 1.44M screens, read by success over the last evaluations."""
    folder = "screens_1.44M"
    lines = [f"per run: mean success over its last {LAST} evaluations; per value: mean ± sample "
             "std over 3 seeds, the seed-mean curve's first step at ≥ 0.8, and the seed-mean "
             "gap from the goal to its nearest landmark (m) at 0.576M / 0.96M", ""]
    progs = programs(folder)
    fig = Figure(figsize=(11, 6))
    axes = fig.subplots(2, len(progs), sharex=True, sharey="row")
    defaults = {}
    for col, (name, (field, default, rows, values)) in enumerate(progs.items()):
        last = {}
        for value in values:
            for alpha, method in ALPHAS.items():
                steps, s = curve(rows, field, value, alpha, "success_rate")
                gsteps, g = curve(rows, field, value, alpha, "goal_landmark_gap")
                last[value, alpha] = x = s[-LAST:].mean(axis=0)
                mean, gap = s.mean(axis=1), seed_mean(g)
                reached = steps[mean >= 0.8]
                at = f"{reached[0] / 1e6:.3f}M" if reached.size else "never"
                gaps = [gap[list(gsteps).index(t)] for t in (576000, 960000)]
                lines.append(f"{name:>12} {field}={value:<5} {method:<8} {x.mean():.2f} ± "
                             f"{x.std(ddof=1):.2f}  0.8 at {at:<7} gap "
                             + " / ".join(f"{v:4.1f}" for v in gaps))
                style = dict(ls="-" if alpha == "0.0" else "--", color=f"C{values.index(value)}")
                axes[0, col].plot(steps / 1e6, mean, label=f"{value} {method}", **style)
                axes[1, col].plot(gsteps / 1e6, gap, **style)
        for value in values:
            if value == default:
                continue
            for alpha, method in ALPHAS.items():
                p = permutation_test(last[value, alpha], last[default, alpha])
                lines.append(f"{name:>12} {field}={value:<5} {method:<8} against {default}: "
                             f"p = {p:.2f}")
        defaults[name] = {a: last[default, a] for a in ALPHAS}
        axes[0, col].set_title(f"{field} (default {default})", fontsize=9)
        axes[0, col].legend(fontsize=6)
        axes[1, col].axhline(5.0, color="gray", lw=0.5)
        axes[1, col].set_xlabel("env steps per seed (M)")
    axes[0, 0].set_ylabel("seed-mean success")
    axes[1, 0].set_ylabel("goal to nearest landmark (m)")
    a, b = defaults.values()
    lines += ["", "the default in the two programs (same flags and seeds): "
              + "; ".join(f"{m} {a[k].mean():.2f} / {b[k].mean():.2f}, p = "
                          f"{permutation_test(a[k], b[k]):.2f}" for k, m in ALPHAS.items())]
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, folder, "screens.png"), dpi=110)
    return lines


LEVERS = {"n_step3": "--n-step 3", "critic_atoms51": "--critic-atoms 51",
          "layer_norm": "--critic-layer-norm"}
BATCH = "batch4096"  # --batch-size 4096 --updates-per-step 0.0625, learning rates listed


def last_success(rows: list, alpha: str, where: tuple = ()) -> tuple[np.ndarray, np.ndarray,
                                                                     np.ndarray]:
    """(steps, seed-mean success curve, per-seed mean of the last evaluations) of one point."""
    steps, _, s = seed_table(select(rows, [*where, ("flr_alpha", alpha)]), "success_rate")
    return steps, s.mean(axis=1), s[-LAST:].mean(axis=0)


def lever_screen() -> list[str]:
    """The opt-in levers and the batch-4,096 shape at 1.44M, against the screens' defaults."""
    lines = [f"per run: mean success over its last {LAST} evaluations; per program and method: "
             "mean ± sample std over 3 seeds, the seed-mean curve's first step at ≥ 0.8, p "
             "against the default points of the two 1.44M screens (random_eps / landmark_eps "
             "programs: the same flags and seeds without the lever), seed-mean Q and critic "
             "loss of the main critics at 0.48M / 1.44M", ""]
    base = {name: read_rows(os.path.join(HERE, "screens_1.44M", f"{name}.csv"))
            for name in SCREENS["screens_1.44M"]}
    control = {a: [last_success(base[n], a, [(f, d)]) for n, (f, d)
                   in SCREENS["screens_1.44M"].items()] for a in ALPHAS}
    points = [(name, flag, ()) for name, flag in LEVERS.items()]
    batch = read_rows(os.path.join(HERE, "levers_1.44M", f"{BATCH}.csv"))
    points += [(BATCH, f"batch 4096, lr ×{float(v) / 1e-3:g}", (("lr_critic", v),))
               for v in sorted({r["lr_critic"] for r in batch}, key=float)]
    data = {name: read_rows(os.path.join(HERE, "levers_1.44M", f"{name}.csv"))
            for name, _, _ in points}
    last = {}  # (label, alpha): per-seed last-5 success
    fig = Figure(figsize=(12, 3.4))
    axes = fig.subplots(1, 2, sharey=True)
    for alpha, method in ALPHAS.items():
        ax = axes[list(ALPHAS).index(alpha)]
        for n, (steps, mean, _) in zip(SCREENS["screens_1.44M"], control[alpha], strict=True):
            ax.plot(steps / 1e6, mean, color="k", lw=1, ls=":" if n == "landmark_eps" else "-",
                    label=f"default ({n} program)")
        for i, (name, label, where) in enumerate(points):
            rows = data[name]
            steps, mean, x = last_success(rows, alpha, where)
            last[label, alpha] = x
            reached = steps[mean >= 0.8]
            at = f"{reached[0] / 1e6:.3f}M" if reached.size else "never"
            p = " / ".join(f"{permutation_test(x, c[2]):.2f}" for c in control[alpha])
            qs = []
            for metric in ("q", "critic_loss"):
                qsteps, _, v = seed_table(select(rows, [*where, ("flr_alpha", alpha)]), metric)
                qs.append(" / ".join(f"{v[list(qsteps).index(t)].mean():.1f}"
                                     for t in (480000, 1440000)))
            lines.append(f"{label:<22} {method:<8} {x.mean():.2f} ± {x.std(ddof=1):.2f}  "
                         f"0.8 at {at:<7} p = {p}  Q {qs[0]}  loss {qs[1]}")
            ax.plot(steps / 1e6, mean, color=f"C{i}", label=label)
        ax.set_title(method, fontsize=9)
        ax.set_xlabel("env steps per seed (M)")
    axes[0].set_ylabel("seed-mean success")
    axes[1].legend(fontsize=7)
    lines.append("")
    for _, label, _ in points:
        lines.append(f"{label:<22} FLR+DHRL against DHRL: p = "
                     f"{permutation_test(last[label, '0.01'], last[label, '0.0']):.2f}")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "levers_1.44M", "levers.png"), dpi=110)
    return lines


def walls(rows: list) -> dict[int, float]:
    """The program's seconds from launch at each evaluation step."""
    return dict(sorted((int(r["step"]), float(r["wall_time"])) for r in rows))


def chunk_seconds(wall: dict[int, float]) -> float:
    """The median seconds from one evaluation to the next, past the initial episodes' two and
    the first training chunk; of a program of 3 chunks (a cost probe), its one training chunk."""
    d = np.diff(list(wall.values()))
    return float(np.median(d[2:] if d.size > 2 else d[1:]))


def first_at(steps: np.ndarray, mean: np.ndarray, wall: dict[int, float]) -> str:
    """``1.382M, 781 s``: the seed-mean curve's first step at ≥ 0.8 and the program's seconds
    there, or ``never``."""
    at = np.flatnonzero(mean >= 0.8)
    return f"{steps[at[0]] / 1e6:.3f}M, {wall[int(steps[at[0]])]:.0f} s" if at.size else "never"


FRESH = {"critic_atoms51": "--critic-atoms 51, 5 seeds",
         "layer_norm": "--critic-layer-norm, 5 seeds",
         "envs64": "--num-envs 64, 3 seeds", "envs128": "--num-envs 128, 3 seeds",
         "envs256": "--num-envs 256, 3 seeds, 1.536M"}
WIDE = {"ttr_wide": "--preset wide, 5 fresh seeds",
        "batch2048_5seeds": "--batch-size 2048, 5 fresh seeds"}
FIGURE = os.path.join(HERE, "..", "fig2_ant3leg_1.92M", "dhrl.csv")


def figure_span(fsteps: np.ndarray, fs: np.ndarray, last: np.ndarray) -> np.ndarray:
    """The figure's ``[steps, seeds]`` success over the evaluations a program's ``last`` steps
    cover: the same steps, else those within their span for a program that ends before the
    figure, else the figure's last :data:`LAST`."""
    if np.isin(last, fsteps).all():
        return fs[np.isin(fsteps, last)]
    if last[-1] < fsteps[-1]:
        return fs[(fsteps >= last[0]) & (fsteps <= last[-1])]
    return fs[-LAST:]


def fresh_screen(folder: str, runs: dict[str, str], png: str) -> list[str]:
    """Programs to 1.92M (``folder``'s ``runs``: CSV name -> label): each method against the
    figure's runs (Fig. 2 left: 16 envs, seeds 5000-5004) over the same last evaluations, and
    FLR+DHRL against DHRL in each program; draws ``folder/png``."""
    lines = [f"per run: mean success over its last {LAST} evaluations; per program and method: "
             "mean ± sample std over seeds, the seed-mean curve's first step at ≥ 0.8 and the "
             "trainer's seconds there, p against Fig. 2 left's 5 runs (16 envs, seeds 5000-5004) "
             "over the same steps' evaluations (where the steps differ: those within the "
             "same span for a program that ends sooner, else their last 5), "
             "FLR+DHRL against DHRL in the program", ""]
    figure = read_rows(FIGURE)
    last = {}
    fig = Figure(figsize=(12, 6.4))
    axes = fig.subplots(2, 2, sharey=True)
    for col, (alpha, method) in enumerate(ALPHAS.items()):
        fsteps, fmean, _ = last_success(figure, alpha)
        axes[0, col].plot(fsteps / 1e6, fmean, color="k", lw=1, label="Fig. 2 left (16 envs)")
        _, _, fs = seed_table(select(figure, [("flr_alpha", alpha)]), "success_rate")
        for i, (name, label) in enumerate(runs.items()):
            rows = read_rows(os.path.join(HERE, folder, f"{name}.csv"))
            steps, mean, x = last_success(rows, alpha)
            last[name, alpha] = x
            wall = walls(rows)
            reached = first_at(steps, mean, wall)
            ref = figure_span(fsteps, fs, steps[-LAST:]).mean(axis=0)
            lines.append(f"{label:<32} {method:<8} {x.mean():.2f} ± {x.std(ddof=1):.2f}  0.8 at "
                         f"{reached:<16} Fig. 2 {ref.mean():.2f}, p = "
                         f"{permutation_test(x, ref):.3f}")
            axes[0, col].plot(steps / 1e6, mean, color=f"C{i}", label=label)
            axes[1, col].plot([wall[int(s)] for s in steps], mean, color=f"C{i}", label=label)
        axes[0, col].set_title(method, fontsize=9)
        axes[0, col].set_xlabel("env steps per seed (M)")
        axes[1, col].set_xlabel("seconds of training (the program's clock, compile included)")
    for ax in axes[:, 0]:
        ax.set_ylabel("seed-mean success")
    axes[0, 1].legend(fontsize=7)
    lines.append("")
    for name, label in runs.items():
        lines.append(f"{label:<32} FLR+DHRL against DHRL: p = "
                     f"{permutation_test(last[name, '0.01'], last[name, '0.0']):.3f}")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, folder, png), dpi=110)
    return lines


def lever_cost() -> list[str]:
    """Seconds per chunk of the main command's shape with each lever (one H200 each), and the
    seed-mean Q of the low level's main critics after each chunk."""
    lines = ["seconds per chunk after the first (the trainer's wall_time differences), chunks "
             "2-4; mean Q of the main critics (low/q) after chunks 3 and 4"]
    for name, flag in (("n_step1", "--n-step 1"), ("n_step3", "--n-step 3"),
                       ("critic_atoms51", "--critic-atoms 51")):
        rows = read_rows(os.path.join(HERE, "lever_cost", f"{name}.csv"))
        t = dict(sorted((int(r["step"]), float(r["wall_time"])) for r in rows))
        times = np.diff(list(t.values()))
        q = [np.mean([float(r["q"]) for r in rows if int(r["step"]) == s]) for s in list(t)[2:]]
        lines.append(f"{flag:<18} " + " / ".join(f"{x:.1f}" for x in times)
                     + f", total {times.sum():.1f}; Q " + " / ".join(f"{v:.1f}" for v in q))
    return lines


LEARNER = {"polyak_noise_lrs": "program 1 (18 runs)", "polyak_noise_lrs_2": "program 2 (12 runs)"}
LEARNER_FIELDS = ("high_lr_actor", "high_lr_critic", "lr_critic", "polyak", "target_noise")


def learner_points(rows: list) -> list[tuple[tuple, str]]:
    """A list sweep's points in run order as ((field, value), ...) and a label naming what each
    changes from the first point (the reference's values)."""
    fields = [f for f in LEARNER_FIELDS if f in rows[0]]
    points = list(dict.fromkeys(tuple((f, r[f]) for f in fields) for r in rows))
    labels = [", ".join(f"{field_label(f)} {value_text(v)}" for (f, v), (_, v0)
                        in zip(p, points[0], strict=True) if v != v0) or "reference values"
              for p in points]
    return list(zip(points, labels, strict=True))


def save_pair(fig: Figure, axes, right: str, legend_size: int, png: str) -> None:
    """Label two panels over env steps (seed-mean success left, ``right`` right), give the
    left its legend and save the figure as ``learner_numbers/png``."""
    axes[0].set_ylabel("seed-mean success")
    axes[1].set_ylabel(right)
    for ax in axes:
        ax.set_xlabel("env steps per seed (M)")
    axes[0].legend(fontsize=legend_size, loc="upper left")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "learner_numbers", png), dpi=110)


def envs128_control() -> np.ndarray:
    """Each seed's mean success of FLR+DHRL in ``levers_1.92M/envs128.csv`` over the
    evaluations at 1.229-1.536M: the wide shape's flags and seeds 9610-9612 without a lever."""
    envs128 = read_rows(os.path.join(HERE, "levers_1.92M", "envs128.csv"))
    steps, _, s = seed_table(select(envs128, [("flr_alpha", "0.01")]), "success_rate")
    return s[(steps >= 1228800) & (steps <= 1536000)].mean(axis=0)


def learner_screen() -> list[str]:
    """The learner's numbers (Polyak, target noise, both levels' learning rates): FLR+DHRL
    alone, two list sweeps of one shape (``wide``), each point against its program's first
    point (the reference's values), the two first points against each other and against
    ``levers_1.92M/envs128.csv`` (the same shape and seeds); the curves of success and of the
    low level's mean Q."""
    lines = [f"FLR+DHRL α=0.01, seeds 9610-9612. Per run: mean success over its last {LAST} "
             "evaluations (1.229-1.536M); per point: mean ± sample std over 3 seeds, the "
             "seed-mean curve's first step at ≥ 0.8 and the program's seconds there, p against "
             "the program's first point, seed-mean Q of the low level's main critics at 0.768M / "
             "1.536M, seed-mean gap from the goal to its nearest landmark (m) at 1.152M, falls "
             "summed over all evaluations (mean over seeds)", ""]
    fig = Figure(figsize=(12, 3.6))
    axes = fig.subplots(1, 2)
    first = {}
    n = 0
    for name, title in LEARNER.items():
        rows = read_rows(os.path.join(HERE, "learner_numbers", f"{name}.csv"))
        wall = walls(rows)
        lines.append(f"== {name}: {title}")
        for where, label in learner_points(rows):
            mine = select(rows, where)
            steps, _, v = seed_table(mine, "success_rate")
            mean, x = v.mean(axis=1), v[-LAST:].mean(axis=0)
            first.setdefault(name, x)
            reached = first_at(steps, mean, wall)
            qsteps, _, q = seed_table(mine, "q")
            _, _, gap = seed_table(mine, "goal_landmark_gap")
            _, _, falls = seed_table(mine, "falls")
            qs = " / ".join(f"{q[list(qsteps).index(t)].mean():.1f}" for t in (768000, 1536000))
            p = permutation_test(x, first[name])
            lines.append(f"  {label:<44} {x.mean():.2f} ± {x.std(ddof=1):.2f}  0.8 at "
                         f"{reached:<15} p = {p:.2f}  Q {qs}  gap "
                         f"{np.nanmean(gap[list(qsteps).index(1152000)]):.1f}  falls "
                         f"{falls.sum(axis=0).mean():.0f}")
            ls = "-" if name == "polyak_noise_lrs" else "--"
            kw = dict(color=f"C{n % 10}", ls=ls, label=f"{label} ({title.split(' (')[0]})")
            axes[0].plot(steps / 1e6, mean, **kw)
            axes[1].plot(qsteps / 1e6, q.mean(axis=1), **kw)
            n += 1
    control = envs128_control()
    a, b = first.values()
    lines += ["", f"first points against each other: {a.mean():.2f} / {b.mean():.2f}, p = "
              f"{permutation_test(a, b):.2f}; levers_1.92M/envs128.csv (FLR+DHRL, the same "
              f"evaluations): {control.mean():.2f} ± {control.std(ddof=1):.2f}, p = "
              f"{permutation_test(a, control):.2f} / {permutation_test(b, control):.2f}"]
    save_pair(fig, axes, "seed-mean Q of the low level's main critics", 6, "screens.png")
    return lines


HER_PERIODS = (  # CSV in learner_numbers, its rows' values, label; the reference first
    ("future_p", (("future_p", "0.8"),), "HER 0.8, periods 40 / 10 (ref.)"),
    ("future_p", (("future_p", "0.5"),), "HER 0.5"),
    ("future_p", (("future_p", "1.0"),), "HER 1.0"),
    ("subgoal_freq20", (), "subgoal period 20"),
    ("subgoal_freq60", (), "subgoal period 60"),
    ("target_period5", (), "target period 5"),
    ("target_period20", (), "target period 20"),
)


def her_periods_screen() -> list[str]:
    """The low level's HER relabel ratio (``--future-p`` 0.8 / 0.5 / 1.0: one list sweep, 9
    runs), the subgoal period (``--subgoal-freq`` 20 / 60) and the target networks' period
    (``--target-update-freq`` 5 / 20), a program of 3 runs each; the reference's 40 and 10 are
    the sweep's first point: FLR+DHRL alone on the ``wide`` shape, each point against the
    reference point, which is also read against ``levers_1.92M/envs128.csv`` (the same flags
    and seeds, an earlier commit); the curves of success and of the low level's reach rate."""
    lines = [f"FLR+DHRL α=0.01, seeds 9610-9612, to 1.536M. Per run: mean success over its last "
             f"{LAST} evaluations (1.229-1.536M); per point: mean ± sample std over 3 seeds, the "
             "seed-mean curve's first step at ≥ 0.8 and its program's seconds there (9 runs for "
             "HER, 3 for a period: not comparable), p against the reference point, each seed's "
             "first success (M), falls summed over all evaluations (mean over seeds)", ""]
    fig = Figure(figsize=(11, 3.6))
    axes = fig.subplots(1, 2)
    ref = None
    for n, (name, where, label) in enumerate(HER_PERIODS):
        rows = read_rows(os.path.join(HERE, "learner_numbers", f"{name}.csv"))
        mine = select(rows, list(where))
        steps, _, v = seed_table(mine, "success_rate")
        mean, x = v.mean(axis=1), v[-LAST:].mean(axis=0)
        ref = x if ref is None else ref
        _, _, falls = seed_table(mine, "falls")
        lines.append(f"{label:<32} {x.mean():.2f} ± {x.std(ddof=1):.2f}  0.8 at "
                     f"{first_at(steps, mean, walls(rows)):<15} p = "
                     f"{permutation_test(x, ref):.2f}  first {first_text(steps, v)}  falls "
                     f"{falls.sum(axis=0).mean():.0f}")
        rsteps, _, reach = seed_table(mine, "reach_frac")
        axes[0].plot(steps / 1e6, mean, color=f"C{n}", label=label)
        axes[1].plot(rsteps / 1e6, seed_mean(reach), color=f"C{n}", label=label)
    control = envs128_control()
    lines += ["", f"reference point against levers_1.92M/envs128.csv (FLR+DHRL, the same "
              f"evaluations): {control.mean():.2f} ± {control.std(ddof=1):.2f}, p = "
              f"{permutation_test(ref, control):.2f}"]
    save_pair(fig, axes, "batch transitions reaching\ntheir subgoal (seed mean)", 7,
              "her_periods.png")
    return lines


POLYAK = {"0.995": "-", "0.99": "--", "0.98": ":"}  # the reference's Polyak first
POLYAK_ALPHAS = {"0.0": "DHRL", "0.005": "FLR+DHRL α=0.005", "0.01": "FLR+DHRL α=0.01"}


def first_successes(steps: np.ndarray, v: np.ndarray) -> list[int | None]:
    """Each seed's first evaluation step with success > 0 (``v``: ``[steps, seeds]``), None
    for a seed without one."""
    return [int(steps[np.argmax(v[:, s] > 0)]) if (v[:, s] > 0).any() else None
            for s in range(v.shape[1])]


def first_text(steps: np.ndarray, v: np.ndarray) -> str:
    """Each seed's first success in M env steps (:func:`first_successes`), ``-`` for none."""
    return " ".join("-" if f is None else f"{f / 1e6:.2f}" for f in first_successes(steps, v))


def polyak_screen(name: str, seeds: str, lost: bool) -> list[str]:
    """Polyak rates × α in one list sweep of the ``wide`` shape, DHRL beside
    (``learner_numbers/{name}.csv``): per α, each Polyak rate against the reference's 0.995 over
    the evaluations the program has (``lost``: it ended early), and each α > 0 against DHRL at
    every rate; the curves of success and of the gap from the goal to its nearest landmark."""
    rows = read_rows(os.path.join(HERE, "learner_numbers", f"{name}.csv"))
    wall = walls(rows)
    end = max(wall)
    alphas = {a: m for a, m in POLYAK_ALPHAS.items() if select(rows, [("flr_alpha", a)])}
    n = len({r["seed"] for r in rows})
    lines = [f"seeds {seeds}, to {end / 1e6:.3f}M" + (" (the program was lost there)" if lost
                                                     else "") + ". Per run: "
             f"mean success over its last {LAST} evaluations "
             f"({sorted(wall)[-LAST] / 1e6:.3f}-{end / 1e6:.3f}M); per point: mean ± sample "
             f"std over {n} seeds, the seed-mean curve's first step at ≥ 0.8 and the program's "
             "seconds there, p against Polyak 0.995 at the same α, each seed's first success "
             "(M), seed-mean Q of the low level's main critics and gap from the goal to its "
             f"nearest landmark (m) at 0.768M / {end / 1e6:.3f}M", ""]
    last = {}  # (alpha, polyak): per-seed last-5 success
    fig = Figure(figsize=(4 * len(alphas), 6))
    axes = fig.subplots(2, len(alphas), sharex=True, sharey="row", squeeze=False)
    for col, (alpha, method) in enumerate(alphas.items()):
        for polyak, ls in POLYAK.items():
            mine = select(rows, [("flr_alpha", alpha), ("polyak", polyak)])
            if not mine:
                continue
            steps, _, v = seed_table(mine, "success_rate")
            mean, x = v.mean(axis=1), v[-LAST:].mean(axis=0)
            last[alpha, polyak] = x
            _, _, q = seed_table(mine, "q")
            _, _, gap = seed_table(mine, "goal_landmark_gap")
            at = [list(steps).index(t) for t in (768000, end)]
            firsts = first_text(steps, v)
            lines.append(f"{method:<17} Polyak {polyak:<6} {x.mean():.2f} ± {x.std(ddof=1):.2f}  "
                         f"0.8 at {first_at(steps, mean, wall):<15} p = "
                         f"{permutation_test(x, last[alpha, '0.995']):.2f}  first {firsts}  "
                         f"Q {q[at[0]].mean():.1f} / {q[at[1]].mean():.1f}  gap "
                         f"{np.nanmean(gap[at[0]]):.1f} / {np.nanmean(gap[at[1]]):.1f}")
            kw = dict(color=f"C{list(POLYAK).index(polyak)}", ls=ls, label=f"Polyak {polyak}")
            axes[0, col].plot(steps / 1e6, mean, **kw)
            axes[1, col].plot(steps / 1e6, seed_mean(gap), **kw)
        axes[0, col].set_title(method, fontsize=9)
        axes[1, col].set_xlabel("env steps per seed (M)")
    lines.append("")
    dhrl = [k for k in last if k[0] == "0.0"]
    for (alpha, polyak), x in last.items():
        if alpha != "0.0":
            lines.append(f"{alphas[alpha]:<17} Polyak {polyak:<6} against DHRL at Polyak "
                         + " / ".join(f"{d[1]}: p = {permutation_test(x, last[d]):.3f}"
                                      for d in dhrl))
    axes[0, 0].set_ylabel("seed-mean success")
    axes[1, 0].set_ylabel("gap from the goal to its\nnearest landmark (m)")
    axes[0, -1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "learner_numbers", f"{name}.png"), dpi=110)
    return lines


def method_rows(path: str, rows: list, alpha: str) -> list:
    """The rows of one method (FLR's α; 0 is DHRL) among ``rows``, the program of CSV ``path``:
    by its ``flr_alpha`` column, or, in a program of one α (no such column), all or none as
    its ``grid.json`` record says."""
    if "flr_alpha" in rows[0]:
        return select(rows, [("flr_alpha", alpha)])
    return rows if same(str(run_record(path)["config"]["flr_alpha"]), alpha) else []


SHAPES = {  # CSV in levers_1.92M: label; envs128 (batch 1,024, 256 wide) is the reference
    "envs128": "batch 1,024, 256 wide",
    "batch2048_u025": "batch 2,048",
    "batch4096_u025": "batch 4,096",
    "hidden512": "512 wide",
}
SHAPE_GAP = (768000, 921600)  # env steps: before the onset, and hidden512's last evaluation


def shape_screen() -> list[str]:
    """Batch 2,048 / 4,096 and 512-wide hidden layers at the ``wide`` shape's 0.25 updates per
    env step (the same updates, each on more samples or a wider net) against ``envs128``: per
    method, each program's last evaluations against ``envs128``'s same evaluations; the
    curves in env steps and in each program's seconds."""
    folder = os.path.join(HERE, "levers_1.92M")
    paths = {name: os.path.join(folder, f"{name}.csv") for name in SHAPES}
    programs = {name: read_rows(path) for name, path in paths.items()}
    lines = ["Seeds 9610-9612, 128 envs per seed, 0.25 updates per env step, one program per "
             "shape (batch 4,096: FLR+DHRL alone). Per run: mean success over the last "
             f"{LAST} evaluations to the program's end (hidden512 and batch4096_u025 were stopped "
             "by their time limits); per program: mean ± sample std over 3 seeds, envs128's over "
             "the same evaluations and p against it, the seed-mean curve's first step at ≥ 0.8 "
             "and the program's seconds there, each seed's first success (M), the seed-mean gap "
             "from the goal to its nearest landmark (m) at "
             + " / ".join(f"{t / 1e6:.3f}M" for t in SHAPE_GAP)
             + ", seconds per chunk (median, past the initial episodes)", ""]
    fig = Figure(figsize=(11, 4))
    axes = fig.subplots(1, 2, sharey=True)
    for alpha, method in ALPHAS.items():
        ref = method_rows(paths["envs128"], programs["envs128"], alpha)
        for n, (name, label) in enumerate(SHAPES.items()):
            rows = method_rows(paths[name], programs[name], alpha)
            if not rows:
                continue
            end = max(int(r["step"]) for r in rows)
            steps, _, v = seed_table(rows, "success_rate")
            rsteps, _, rv = seed_table([r for r in ref if int(r["step"]) <= end], "success_rate")
            x, rx = v[-LAST:].mean(axis=0), rv[-LAST:].mean(axis=0)
            _, _, gap = seed_table(rows, "goal_landmark_gap")
            at = [list(steps).index(t) for t in SHAPE_GAP]
            wall = walls(rows)
            per_chunk = chunk_seconds(wall)
            runs = len({(r["seed"], r.get("flr_alpha")) for r in programs[name]})
            lines.append(f"{method:<8} {label:<22} {runs} runs, to {end / 1e6:.3f}M  "
                         f"{x.mean():.2f} ± {x.std(ddof=1):.2f} "
                         + ("(the reference)" if name == "envs128" else
                            f"(envs128 {rx.mean():.2f}, p = {permutation_test(x, rx):.2f})")
                         + "  0.8 at "
                         f"{first_at(steps, v.mean(axis=1), wall):<15} first "
                         f"{first_text(steps, v)}  gap {np.nanmean(gap[at[0]]):.1f} / "
                         f"{np.nanmean(gap[at[1]]):.1f}  {per_chunk:.1f} s per chunk")
            kw = dict(color=f"C{n}", ls="-" if alpha == "0.01" else ":",
                      label=f"{label}, {method}")
            axes[0].plot(steps / 1e6, v.mean(axis=1), **kw)
            axes[1].plot([wall[int(t)] for t in steps], v.mean(axis=1), **kw)
        lines.append("")
    axes[0].set_xlabel("env steps per seed (M)")
    axes[1].set_xlabel("the program's seconds from launch")
    axes[0].set_ylabel("seed-mean success (3 seeds)")
    for ax in axes:
        ax.axhline(0.8, color="gray", lw=0.5)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "shapes.png"), dpi=110)
    return lines[:-1]


CONFIRMS = (  # 5-seed program (CSV here), its label, the reference's label, output (no suffix)
    ("wide_preset/batch2048_5seeds", "batch 2,048 (seeds 9640-9644)",
     "batch 1,024 (seeds 9800-9804)", "wide_preset/batch2048"),
    ("learner_numbers/target_period5_5seeds", "target period 5 (seeds 9800-9804)",
     "target period 10 (seeds 9800-9804)", "learner_numbers/target_period5_5seeds"),
    ("learner_numbers/obs_norm_5seeds", "--obs-norm (seeds 9800-9804)",
     "raw inputs (seeds 9800-9804)", "learner_numbers/obs_norm_5seeds"),
    ("learner_numbers/obs_norm_period5_5seeds", "--obs-norm, target period 5 (seeds 9800-9804)",
     "raw inputs, target period 10 (seeds 9800-9804)", "learner_numbers/obs_norm_period5_5seeds"),
    ("learner_numbers/obs_norm_period5_fresh", "--obs-norm, target period 5 (seeds 9950-9954)",
     "raw inputs, target period 10 (seeds 9800-9804)", "learner_numbers/obs_norm_period5_fresh"),
)


def wide_confirm(path: str, label: str, ref_label: str, out: str) -> list[str]:
    """A lever on 5 fresh seeds, DHRL beside FLR+DHRL (``path``), against the ``wide``
    preset's reference on its 5 fresh seeds (``wide_preset/ttr_wide``) over the same
    evaluations: per method and program the last evaluations' success, p between the programs,
    FLR+DHRL against DHRL in each; 0.8 at, each seed's first success, seconds per chunk; the
    seed-mean curves in ``out.png``."""
    runs = {"wide_preset/ttr_wide": ref_label, path: label}
    programs = {n: read_rows(os.path.join(HERE, f"{n}.csv")) for n in runs}
    end = min(max(int(r["step"]) for r in rows) for rows in programs.values())
    lines = [f"--preset wide, DHRL beside FLR+DHRL, 5 seeds per program; per run: mean success "
             f"over the last {LAST} evaluations to {end / 1e6:.3f}M (the shorter program's end), "
             "per program: mean ± sample std over seeds; p: exact permutation test of the "
             "difference of means (5 against 5)", ""]
    fig = Figure(figsize=(6, 3.8))
    ax = fig.add_subplot()
    last = {}
    width = max(map(len, runs.values()))
    for n, (name, text) in enumerate(runs.items()):
        rows = [r for r in programs[name] if int(r["step"]) <= end]
        wall = walls(programs[name])
        per_chunk = chunk_seconds(wall)
        for alpha, method in ALPHAS.items():
            steps, mean, x = last_success(rows, alpha)
            last[name, alpha] = x
            _, _, v = seed_table(select(rows, [("flr_alpha", alpha)]), "success_rate")
            lines.append(f"{text:<{width}} {method:<8} {x.mean():.2f} ± {x.std(ddof=1):.2f}  "
                         f"0.8 at {first_at(steps, mean, wall):<15} first "
                         f"{first_text(steps, v)}")
            ax.plot(steps / 1e6, v.mean(axis=1), color=f"C{n}",
                    ls="-" if alpha == "0.01" else ":", label=f"{text}, {method}")
        lines.append(f"{text:<{width}} FLR+DHRL against DHRL: p = "
                     f"{permutation_test(last[name, '0.01'], last[name, '0.0']):.3f}; "
                     f"{per_chunk:.1f} s per chunk (10 runs)")
    for alpha, method in ALPHAS.items():
        p = permutation_test(last[path, alpha], last["wide_preset/ttr_wide", alpha])
        lines.append(f"{label.split(' (')[0]} against {ref_label.split(' (')[0]}, {method}: "
                     f"p = {p:.3f}")
    ax.axhline(0.8, color="gray", lw=0.5)
    ax.set_xlabel("env steps per seed (M)")
    ax.set_ylabel("seed-mean success (5 seeds)")
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, f"{out}.png"), dpi=110)
    return lines


TUNED = (  # CSV in tuned_preset/, label, launch clock: rows file or time_to_result JSON
    ("main_tuned", "main command, seeds 0-4, one H200", "main_tuned_rows.txt"),
    ("main_tuned_2gpu", "main command, seeds 0-4, 2 H200s", "main_tuned_2gpu_rows.txt"),
    ("ttr_tuned", "time_to_result, seeds 9950-9954, one H200", "time_to_result_h200.json"),
    ("ttr_tuned_ant4leg", "the same on ant4leg, one H200", "time_to_result_ant4leg_h200.json"),
    ("main_warm", "main command, warm cache, one H200", "main_warm_rows.txt"),
    ("main_warm_2gpu", "main command, warm cache, 2 H200s", "main_warm_2gpu_rows.txt"),
    ("ttr_warm_2gpu", "time_to_result, warm cache, 2 H200s", "time_to_result_warm_h200x2.json"),
    ("ttr_early", "time_to_result, early graph, one H200", "time_to_result_early_h200.json"),
    ("ttr_confirm", "time_to_result, early graph, to 1.92M", "time_to_result_confirm_h200.json"),
    ("main_early", "main command, early graph, one H200", "main_early_rows.txt"),
    ("main_upd05", "main command, 0.5 updates per env step", "main_upd05_rows.txt"),
)
AGAINST_MAIN = {  # the same seeds and command as main_tuned but one change: (CSV, its name)
    "main_early": "early graph", "main_upd05": "0.5 updates per env step"}


def launch_seconds(clock: str, steps: np.ndarray, seeds: int) -> dict[int, float]:
    """Seconds from launch at which each evaluation step's rows were in metrics.csv: from a
    job's rows file (``launch T`` then ``rows LINES T`` whenever the file grew, header
    included), or a time_to_result JSON's curve."""
    path = os.path.join(HERE, "tuned_preset", clock)
    if clock.endswith(".json"):
        with open(path) as f:
            return {int(c["env_steps"]): c["seconds"] for c in json.load(f)["curve"]}
    with open(path) as f:
        marks = [line.split() for line in f if line.strip()]
    launch = float(marks[0][1])
    grown = [(int(n), float(t) - launch) for kind, n, t in marks[1:] if kind == "rows"]
    return {int(s): next(t for n, t in grown if n >= 1 + seeds * (k + 1))
            for k, s in enumerate(steps)}


def first_from_launch(steps: np.ndarray, mean: np.ndarray, rows: list,
                      since: dict[int, float]) -> str:
    """:func:`first_at` with the seconds from launch there (``since``: :func:`launch_seconds`)."""
    reached, at = first_at(steps, mean, walls(rows)), np.flatnonzero(mean >= 0.8)
    if at.size:
        reached += f", {since[int(steps[at[0]])]:.0f} s from launch"
    return reached


def tuned_screen() -> list[str]:
    """The ``tuned`` preset as users run it: the main command (FLR+DHRL alone) on one and on
    two H200s, and time_to_result.py (DHRL beside FLR+DHRL in one program) on one H200 on
    each maze, each launched into an empty compilation cache; then the main command (one and
    two H200s) and the tripod time_to_result (two) launched again, every program loaded from
    the cache; and with the first graph after one random round (:func:`graph_start_screen`),
    one H200 each, into an empty cache: the tripod time_to_result on two sets of 5 fresh seeds
    (one to 1.92M) and the main command (seeds 0-4, against it as written); the main command
    with twice the updates per env step (one H200, empty cache, seeds 0-4). Per program
    and method: the last evaluations' success, 0.8 at (env steps, the trainer's seconds,
    seconds from launch), each seed's first success; FLR+DHRL against DHRL; the one-H200
    tripod program against the same flags and seeds on 2 H200s
    (``learner_numbers/obs_norm_period5_fresh``) over the same evaluations."""
    lines = [f"per run: mean success over its last {LAST} evaluations; per program and method: "
             "mean ± sample std over seeds; 0.8 at: the seed-mean curve's first step at ≥ 0.8, "
             "the trainer's seconds there and the seconds from launch (compiling included); "
             "first: each seed's first success (M env steps); p: exact permutation test of the "
             "difference of means", ""]
    fig = Figure(figsize=(12, 5.2))
    axes = fig.subplots(1, 2, sharey=True)
    width = max(len(label) for _, label, _ in TUNED)
    last = {}
    for i, (name, label, clock) in enumerate(TUNED):
        rows = read_rows(os.path.join(HERE, "tuned_preset", f"{name}.csv"))
        methods = ALPHAS if "flr_alpha" in rows[0] else {None: "FLR+DHRL"}
        for alpha, method in methods.items():
            where = [] if alpha is None else [("flr_alpha", alpha)]
            steps, _, v = seed_table(select(rows, where), "success_rate")
            mean, x = v.mean(axis=1), v[-LAST:].mean(axis=0)
            last[name, method] = x
            since = launch_seconds(clock, steps, v.shape[1])
            reached = first_from_launch(steps, mean, rows, since)
            lines.append(f"{label:<{width}} {method:<8} {x.mean():.2f} ± {x.std(ddof=1):.2f} "
                         f"({steps[-LAST] / 1e6:.3f}-{steps[-1] / 1e6:.3f}M)  0.8 at "
                         f"{reached:<31} first {first_text(steps, v)}")
            style = dict(color=f"C{i}", ls=":" if method == "DHRL" else "-",
                         label=f"{label}, {method}")
            axes[0].plot(steps / 1e6, mean, **style)
            axes[1].plot([since[int(s)] for s in steps], mean, **style)
        if len(methods) == 2:
            lines.append(f"{label:<{width}} FLR+DHRL against DHRL: p = "
                         f"{permutation_test(last[name, 'FLR+DHRL'], last[name, 'DHRL']):.3f}")
    lines += ["", *map(against_main, AGAINST_MAIN), ""]
    fresh = read_rows(os.path.join(HERE, "learner_numbers", "obs_norm_period5_fresh.csv"))
    end = max(int(r["step"]) for r in read_rows(os.path.join(HERE, "tuned_preset",
                                                              "ttr_tuned.csv")))
    for alpha, method in ALPHAS.items():
        _, _, x = last_success([r for r in fresh if int(r["step"]) <= end], alpha)
        p = permutation_test(last["ttr_tuned", method], x)
        lines.append(f"the same flags and seeds on 2 H200s (learner_numbers/obs_norm_period5_fresh)"
                     f", {method}, to {end / 1e6:.3f}M: {x.mean():.2f} ± {x.std(ddof=1):.2f}; "
                     f"one H200 against it: p = {p:.3f}")
    for ax in axes:
        ax.axhline(0.8, color="gray", lw=0.5)
    axes[0].set_xlabel("env steps per seed (M)")
    axes[1].set_xlabel("seconds from launch (compiling included)")
    axes[0].set_ylabel("seed-mean success (5 seeds)")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=3, fontsize=7)
    fig.tight_layout(rect=(0, 0.2, 1, 1))
    fig.savefig(os.path.join(HERE, "tuned_preset", "tuned.png"), dpi=110)
    return lines


def flr_success(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(steps, ``[steps, seeds]`` success) of FLR+DHRL in program ``name`` of tuned_preset/
    (its alpha 0.01 runs where DHRL trained beside it)."""
    rows = read_rows(os.path.join(HERE, "tuned_preset", f"{name}.csv"))
    if "flr_alpha" in rows[0]:
        rows = select(rows, [("flr_alpha", "0.01")])
    steps, _, v = seed_table(rows, "success_rate")
    return steps, v


def against_main(name: str) -> str:
    """Program ``name`` of :data:`AGAINST_MAIN` against the main command as written (seeds
    0-4), over ``name``'s last evaluations."""
    (main_steps, main), (steps, v) = flr_success("main_tuned"), flr_success(name)
    x = v[-LAST:].mean(axis=0)
    y = main[main_steps <= steps[-1]][-LAST:].mean(axis=0)
    return (f"main command, {AGAINST_MAIN[name]} against as written, seeds 0-4, "
            f"{steps[-LAST] / 1e6:.3f}-{steps[-1] / 1e6:.3f}M: {x.mean():.2f} ± "
            f"{x.std(ddof=1):.2f} against {y.mean():.2f} ± {y.std(ddof=1):.2f}, "
            f"p = {permutation_test(x, y):.3f}")


GRAPH_START = (  # (CSV in tuned_preset/, label): the main command, then the early graph
    (("onset_control", "main command, seeds 0-4"),
     ("onset_early", "first graph after one random round, seeds 0-4")),
    (("onset_control_fresh", "main command, seeds 9970-9974"),
     ("onset_early_fresh", "first graph after one random round, seeds 9970-9974")),
)
GAPS = ("goal_landmark_gap", "sample_goal_gap", "replay_goal_gap")
POOL = {  # every tripod program of ``tuned`` in tuned_preset/, without and with the early graph
    "as written": ("main_tuned", "main_tuned_2gpu", "ttr_tuned", "main_warm", "main_warm_2gpu",
                   "ttr_warm_2gpu", "onset_control", "onset_control_fresh"),
    "early graph": ("onset_early", "onset_early_fresh", "ttr_early", "ttr_confirm", "main_early"),
}


def early_graph_pool() -> list[str]:
    """FLR+DHRL in every tripod program of ``tuned`` here, as written and with the early
    graph: per program its seeds' mean first success and the seed-mean curve's first step at
    0.8; the two groups' program means compared (reruns of a seed set count as programs)."""
    lines = ["FLR+DHRL in every tripod program of tuned here, 5 seeds each (reruns of a seed set "
             "count as programs): the seeds' mean first success (M); 0.8 at: the seed-mean "
             "curve's first step at >= 0.8 ('>': not by the program's last evaluation)"]
    firsts = {}
    for group, names in POOL.items():
        firsts[group] = []
        for name in names:
            steps, v = flr_success(name)
            first = [f for f in first_successes(steps, v) if f is not None]
            at = np.flatnonzero(v.mean(axis=1) >= 0.8)
            reach = f"{steps[at[0]] / 1e6:.3f}M" if at.size else f">{steps[-1] / 1e6:.3f}M"
            firsts[group].append(np.mean(first))
            none = v.shape[1] - len(first)
            lines.append(f"  {group:<11} {name:<19} first {np.mean(first) / 1e6:.3f}M"
                         + (f" ({none} seeds without)" if none else "") + f"  0.8 at {reach}")
    a, b = (np.array(x) for x in firsts.values())
    rounds = flr_success(POOL["as written"][0])[0][0]  # the first evaluation: one round
    lines.append(f"mean first success over programs: as written {a.mean() / 1e6:.3f}M, early "
                 f"graph {b.mean() / 1e6:.3f}M ({(a.mean() - b.mean()) / rounds:.2f} rounds "
                 f"earlier); p = {permutation_test(b, a):.3f}")
    return lines


def graph_start_screen() -> list[str]:
    """The first graph after one random round of 128 episodes (``--graph-start-steps 76800
    --initial-episodes 128``) against the main command's (two random rounds, the graph from
    the fourth), the same seeds, one program at a time on one H200 host: per program each
    seed's first success and the seed-mean success and gaps from the goal to its nearest
    landmark, sampled state and replay state at every evaluation; per seed the shift of the
    first success."""
    lines = ["per evaluation, seed means: success; the true path (m) from the goal to its "
             "nearest landmark, landmark-sample state and replay state (complete episodes); "
             "graph nodes. 0.8 at: the seed-mean curve's first step at >= 0.8, the trainer's "
             "seconds and the seconds from launch; first: each seed's first success (M)", ""]
    fig = Figure(figsize=(12, 4.4))
    axes = fig.subplots(1, 2)
    for i, pair in enumerate(GRAPH_START):
        firsts = []
        for (name, label), ls in zip(pair, ("-", "--"), strict=True):
            rows = read_rows(os.path.join(HERE, "tuned_preset", f"{name}.csv"))
            steps, _, v = seed_table(rows, "success_rate")
            mean = v.mean(axis=1)
            firsts.append(first_successes(steps, v))
            since = launch_seconds(f"{name}_rows.txt", steps, v.shape[1])
            reached = first_from_launch(steps, mean, rows, since)
            lines += [f"{name}: {label}; 0.8 at {reached}; first {first_text(steps, v)}",
                      "  step (M)  success  landmark  sample  replay  nodes"]
            gaps = [seed_mean(seed_table(rows, g)[2]) for g in (*GAPS, "graph_nodes")]
            lines += [f"  {s / 1e6:8.3f}  {m:7.2f}  " + "  ".join(
                f"{g[k]:{w}.1f}" for g, w in zip(gaps, (8, 6, 6, 5), strict=True))
                for k, (s, m) in enumerate(zip(steps, mean, strict=True))]
            built = ~np.isnan(gaps[0])
            lines.append(f"  landmark gap minus replay gap over the builds: "
                         f"{np.min(gaps[0][built] - gaps[2][built]):.1f} to "
                         f"{np.max(gaps[0][built] - gaps[2][built]):.1f} m")
            color = f"C{2 * i + (ls == '--')}"
            axes[0].plot(steps / 1e6, mean, ls=ls, color=color, label=label)
            axes[1].plot(steps / 1e6, gaps[0], ls=ls, color=color)
            axes[1].plot(steps / 1e6, gaps[2], ls=":", color=color, lw=0.8)
        shift = [(c - e) / steps[0] for c, e in zip(*firsts, strict=True)
                 if c is not None and e is not None]
        lines += [f"first success, main command minus early graph, per seed (rounds of "
                  f"{steps[0]:,} env steps): {' '.join(f'{d:g}' for d in shift)}; mean "
                  f"{np.mean(shift):.2f}", ""]
    lines += early_graph_pool()
    axes[0].axhline(0.8, color="gray", lw=0.5)
    axes[1].axhline(5.0, color="gray", lw=0.5)
    axes[0].set_ylabel("seed-mean success (5 seeds)")
    axes[1].set_ylabel("goal to nearest landmark (m)\ndotted: to nearest replay state")
    for ax in axes:
        ax.set_xlabel("env steps per seed (M)")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=2, fontsize=7)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    fig.savefig(os.path.join(HERE, "tuned_preset", "graph_start.png"), dpi=110)
    return lines


CHUNK_COST = (  # CSV here, label: programs of the wide shape (128 envs per seed, 0.25 updates
    # per env step, no checkpoints), batch 1,024 unless the label says otherwise
    ("learner_numbers/subgoal_freq20", "subgoal period 20"),
    ("learner_numbers/subgoal_freq60", "subgoal period 60"),
    ("learner_numbers/target_period5", "target period 5"),
    ("learner_numbers/target_period20", "target period 20"),
    ("levers_1.92M/envs128", ""), ("learner_numbers/future_p", ""), ("wide_preset/ttr_wide", ""),
    ("learner_numbers/polyak_noise_lrs_2", ""), ("learner_numbers/polyak_noise_lrs", ""),
    ("learner_numbers/polyak5", ""), ("learner_numbers/polyak_alpha", ""),
    ("levers_1.92M/batch2048_u025", "batch 2,048"), ("wide_preset/batch2048_5seeds", "batch 2,048"),
    ("levers_1.92M/batch4096_u025", "batch 4,096"), ("lever_cost/batch8192", "batch 8,192"),
    ("lever_cost/batch16384", "batch 16,384"),
)
BATCH_COLORS = {"batch 2,048": "C1", "batch 4,096": "C2", "batch 8,192": "C3",
                "batch 16,384": "C4"}


def chunk_cost() -> list[str]:
    """Seconds per chunk (76,800 env steps and 19,200 low-level updates per run, its
    evaluation included) against the runs vmapped in the program, one H200 each, and a line
    fitted to the batch-1,024 programs: its intercept is what a chunk costs whatever the
    number of runs, the floor of one program's sequential updates and physics."""
    lines = ["program (commit): runs vmapped, median seconds per chunk from one evaluation to "
             "the next (evaluation included), past the first two (a 3-chunk cost probe: its "
             "third chunk)", ""]
    points, probes = [], []
    fig = Figure(figsize=(5.5, 3.8))
    ax = fig.add_subplot()
    for path, label in CHUNK_COST:
        rows = read_rows(os.path.join(HERE, f"{path}.csv"))
        runs = sum(r["step"] == rows[0]["step"] for r in rows)
        wall = walls(rows)
        sec = chunk_seconds(wall)
        commit = run_record(os.path.join(HERE, f"{path}.csv"))["git"]["commit"][:7]
        lines.append(f"{path + ' (' + commit + ')':<46} {runs:>3} {sec:6.1f}  {label}".rstrip())
        if not label.startswith("batch"):
            points.append((runs, sec))
        if path.startswith("lever_cost/"):  # a cost probe: 1.152M at its pace
            probes.append(f"{label}: to 1.152M (2 initial rounds, then 13 chunks) at this pace: "
                          f"{wall[153600] + 13 * sec:.0f} s")
        ax.scatter([runs], [sec], color=BATCH_COLORS.get(label, "C0"), s=18)
    runs, sec = np.array(points).T
    b, a = np.polyfit(runs, sec, 1)
    lines += ["", f"batch 1,024: seconds per chunk ~ {a:.1f} + {b:.2f} x runs (least squares over "
              f"{len(points)} programs); one run: {a + b:.1f} s, 5 runs: {a + 5 * b:.1f} s",
              *probes]
    x = np.arange(1, runs.max() + 1)
    ax.plot(x, a + b * x, color="C0", lw=1, label=f"batch 1,024: {a:.1f} + {b:.2f} × runs")
    for label, color in BATCH_COLORS.items():
        ax.scatter([], [], color=color, s=18, label=label)
    ax.set_xlim(0, runs.max() + 1)
    ax.set_ylim(0, None)
    ax.set_xlabel("runs vmapped in the program (seeds × sweep points)")
    ax.set_ylabel("seconds per chunk, one H200")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "chunk_cost.png"), dpi=110)
    return lines


RESULTS = os.path.join(HERE, "..")
ONSET = (  # label, CSV under experiments/results, updates per env step, other columns' values
    ("16 envs (Fig. 2 left)", "fig2_ant3leg_1.92M/dhrl.csv", 0.25, ()),
    ("16 envs (paper ratio)", "paper_ratio_1.92M/dhrl.csv", 1.0, ()),
    ("64 envs", "learning_levers/levers_1.92M/envs64.csv", 0.25, ()),
    ("128 envs", "learning_levers/levers_1.92M/envs128.csv", 0.25, ()),
    ("128 envs (wide, 5 seeds)", "learning_levers/wide_preset/ttr_wide.csv", 0.25, ()),
    ("256 envs", "learning_levers/levers_1.92M/envs256.csv", 0.25, ()),
    ("128 envs, batch 2,048", "learning_levers/levers_1.92M/batch2048_u025.csv", 0.25, ()),
    ("128 envs, batch 4,096", "learning_levers/levers_1.92M/batch4096_u025.csv", 0.25, ()),
    ("128 envs, 512 wide", "learning_levers/levers_1.92M/hidden512.csv", 0.25, ()),
    ("batch 2,048, 5 fresh seeds", "learning_levers/wide_preset/batch2048_5seeds.csv", 0.25,
     ()),
    ("128 envs, batch 1,024", "learning_levers/half_updates/updates0.125_batch1024.csv", 0.125,
     (("lr_critic", "0.001"),)),
    ("128 envs, batch 2,048", "learning_levers/half_updates/updates0.125_batch2048.csv", 0.125,
     (("lr_critic", "0.001"),)),
    ("64 envs, batch 4,096", "learning_levers/levers_1.44M/batch4096.csv", 0.0625,
     (("lr_critic", "0.001"),)),
    ("128 envs, HER 0.8 (ref.)", "learning_levers/learner_numbers/future_p.csv", 0.25,
     (("future_p", "0.8"),)),
    ("128 envs, HER 0.5", "learning_levers/learner_numbers/future_p.csv", 0.25,
     (("future_p", "0.5"),)),
    ("128 envs, HER 1.0", "learning_levers/learner_numbers/future_p.csv", 0.25,
     (("future_p", "1.0"),)),
    ("128 envs, subgoal period 20", "learning_levers/learner_numbers/subgoal_freq20.csv", 0.25,
     ()),
    ("128 envs, subgoal period 60", "learning_levers/learner_numbers/subgoal_freq60.csv", 0.25,
     ()),
    ("128 envs, target period 5", "learning_levers/learner_numbers/target_period5.csv", 0.25, ()),
    ("128 envs, target period 20", "learning_levers/learner_numbers/target_period20.csv", 0.25,
     ()),
    ("target period 5, 5 seeds", "learning_levers/learner_numbers/target_period5_5seeds.csv",
     0.25, ()),
    ("obs-norm, 5 seeds", "learning_levers/learner_numbers/obs_norm_5seeds.csv", 0.25, ()),
    ("obs-norm, period 5", "learning_levers/learner_numbers/obs_norm_period5_5seeds.csv", 0.25,
     ()),
    ("obs-norm, period 5, fresh", "learning_levers/learner_numbers/obs_norm_period5_fresh.csv",
     0.25, ()),
)


def onset_updates() -> list[str]:
    """Each seed's first evaluation with any success, in env steps and in low-level updates
    per run (steps x updates per env step), per program and method; a seed without one counts
    as "none by" its program's last evaluation. The reference's learning rates throughout."""
    lines = ["first evaluation with success > 0, per seed (sorted): env steps (M) / low-level "
             "updates per run (k); 'none by': the last evaluation of a seed without one", ""]
    fig = Figure(figsize=(11, 7))
    axes = fig.subplots(1, 2)
    colors = [*colormaps["tab20"].colors, *colormaps["Dark2"].colors]  # a color per program
    for n, (label, path, ratio, where) in enumerate(ONSET):
        rows = read_rows(os.path.join(RESULTS, path))
        for alpha, method in ALPHAS.items():
            mine = select(method_rows(os.path.join(RESULTS, path), rows, alpha), list(where))
            if not mine:
                continue
            steps, _, v = seed_table(mine, "success_rate")
            first = first_successes(steps, v)
            hit = np.array(sorted(f for f in first if f is not None))
            none = len(first) - len(hit)
            text = " ".join(f"{f / 1e6:.2f}/{f * ratio / 1e3:.0f}" for f in hit)
            if none:
                text += f"{' ' if text else ''}none by {steps[-1] / 1e6:.2f}/" \
                        f"{steps[-1] * ratio / 1e3:.0f} ({none} of {len(first)})"
            lines.append(f"{label:<28} {ratio:<6g} {method:<8} {text}")
            marker = "o" if alpha == "0.01" else "x"
            x = ratio * (1.04 if alpha == "0.01" else 0.96)  # the methods side by side
            for ax, scale in zip(axes, (1e6, 1e3 / ratio), strict=True):
                ax.scatter(np.full(len(hit), x), hit / scale, marker=marker, color=colors[n],
                           s=22, label=f"{label}, {method}")
                if none:  # not yet: the run's end, a lower bound
                    ax.scatter([x], [steps[-1] / scale], marker="^", facecolors="none",
                               edgecolors=colors[n], s=40)
    for ax, what in zip(axes, ("env steps per seed (M)", "low-level updates per run (k)"),
                        strict=True):
        ax.set_xscale("log", base=2)
        ax.set_xticks([0.0625, 0.125, 0.25, 1.0], ["1/16", "1/8", "1/4", "1"])
        ax.set_xlabel("updates per env step")
        ax.set_ylabel(f"first success: {what}")
        ax.set_ylim(bottom=0)
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, ncol=4, loc="lower center")
    axes[0].set_title("o FLR+DHRL, x DHRL; open triangle: none by the program's end "
                      "(a lower bound)", fontsize=9)
    fig.tight_layout(rect=(0, 0.27, 1, 1))
    fig.savefig(os.path.join(HERE, "onset_updates.png"), dpi=110)
    return lines


def main() -> None:
    for path, lines in (("screens_0.58M/screens.txt", gap_screen()),
                        ("screens_1.44M/screens.txt", success_screen()),
                        ("levers_1.44M/levers.txt", lever_screen()),
                        ("levers_1.92M/levers.txt",
                         fresh_screen("levers_1.92M", FRESH, "levers.png")),
                        ("wide_preset/preset.txt",
                         fresh_screen("wide_preset", WIDE, "preset.png")),
                        ("learner_numbers/screens.txt", learner_screen()),
                        ("learner_numbers/polyak_alpha.txt",
                         polyak_screen("polyak_alpha", "9610-9612", lost=True)),
                        ("levers_1.92M/shapes.txt", shape_screen()),
                        ("learner_numbers/polyak5.txt",
                         polyak_screen("polyak5", "9620-9624", lost=False)),
                        *((f"{out}.txt", wide_confirm(*c, out)) for *c, out in CONFIRMS),
                        ("tuned_preset/tuned.txt", tuned_screen()),
                        ("tuned_preset/graph_start.txt", graph_start_screen()),
                        ("learner_numbers/her_periods.txt", her_periods_screen())):
        with open(os.path.join(HERE, path), "w") as f:
            f.write("\n".join(lines) + "\n")
        print("\n".join(lines), end="\n\n")
    for path, lines in (("lever_cost/cost.txt", lever_cost()),
                        ("onset_updates.txt", onset_updates()),
                        ("chunk_cost.txt", chunk_cost())):
        with open(os.path.join(HERE, path), "w") as f:
            f.write("\n".join(lines) + "\n")
        print("\n".join(lines), end="\n\n")


if __name__ == "__main__":
    main()
