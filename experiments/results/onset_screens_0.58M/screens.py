"""The exploration and critic learning-rate screens of docs/results.md ("What the onset of
success waits for"): per program and swept value, the seed-mean gap from the goal to its nearest
landmark (``goal_landmark_gap``, m) at 0.288–0.576M env steps, DHRL (α = 0) and FLR+DHRL
(α = 0.01) apart and pooled; the pooled 6 runs of each value against the same program's
default by an exact two-sided permutation test; the default's spread over the four programs
(the same flags and seeds). Writes ``screens.txt`` and ``screens.png`` beside it:

    PYTHONPATH=. python experiments/results/onset_screens_0.58M/screens.py
"""
import os
import warnings

import numpy as np
from matplotlib.figure import Figure

from experiments.claims import permutation_test
from flrjax.analysis import read_rows, seed_table, select

HERE = os.path.dirname(os.path.abspath(__file__))
PROGRAMS = {  # CSV: (swept column, its default)
    "subgoal_noise": ("subgoal_noise_eps", "2.0"),
    "random_eps": ("random_eps", "0.2"),
    "noise_eps": ("noise_eps", "0.1"),
    "lr_critic": ("lr_critic", "0.001"),
}
STEPS = (288000, 384000, 480000, 576000)
ALPHAS = ("0.0", "0.01")


def gaps(rows: list, field: str, value: str, alpha: str) -> tuple[np.ndarray, np.ndarray]:
    """(steps, ``[steps, seeds]`` gaps) of one sweep point."""
    steps, _, v = seed_table(select(rows, [(field, value), ("flr_alpha", alpha)]),
                             "goal_landmark_gap")
    return steps, v


def main() -> None:
    lines = ["seed-mean goal_landmark_gap (m) at " + " / ".join(f"{s / 1e6:.3f}M" for s in STEPS)
             + "; pooled: both methods' 6 runs at 0.576M, mean ± sample std; p: the difference"
             " of means, permuted (experiments/claims.py)", ""]
    fig = Figure(figsize=(13, 3.2))
    axes = fig.subplots(1, len(PROGRAMS), sharey=True)
    defaults, pooled_values = [], {}
    for ax, (name, (field, default)) in zip(axes, PROGRAMS.items(), strict=True):
        rows = read_rows(os.path.join(HERE, f"{name}.csv"))
        values = sorted({r[field] for r in rows}, key=float)
        last = {}
        for value in values:
            pooled = []
            for alpha in ALPHAS:
                steps, v = gaps(rows, field, value, alpha)
                with warnings.catch_warnings():  # no graph yet in the first chunks: NaN
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mean = np.nanmean(v, axis=1)
                at = [mean[list(steps).index(s)] for s in STEPS]
                pooled.append(v[list(steps).index(STEPS[-1])])
                lines.append(f"{name:>13} {field}={value:<6} α={alpha:<4} "
                             + " ".join(f"{g:5.1f}" for g in at))
                ax.plot(steps / 1e6, mean, ls="-" if alpha == "0.0" else "--",
                        color=f"C{values.index(value)}",
                        label=f"{value} {'DHRL' if alpha == '0.0' else 'FLR+DHRL'}")
            last[value] = np.concatenate(pooled)
        defaults.append(last[default])
        pooled_values[name] = last
        ax.set_title(f"{field} (default {default})", fontsize=9)
        ax.set_xlabel("env steps per seed (M)")
        ax.axhline(5.0, color="gray", lw=0.5)
        ax.legend(fontsize=6)
    axes[0].set_ylabel("goal to nearest landmark (m)")
    every = np.concatenate(defaults)
    for (name, (field, default)), d in zip(PROGRAMS.items(), defaults, strict=True):
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
    fig.savefig(os.path.join(HERE, "screens.png"), dpi=110)
    with open(os.path.join(HERE, "screens.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
