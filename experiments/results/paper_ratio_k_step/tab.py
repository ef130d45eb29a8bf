"""Table numbers of the k-step reading beside reading (a) and the infinite reading, to 1.92M,
at the paper's ratio and (reading (a) and the infinite one) under the figure protocol
(docs/results.md): PYTHONPATH=. python experiments/results/paper_ratio_k_step/tab.py"""
import warnings

import numpy as np

from experiments.claims import permutation_test
from flrjax.analysis import read_rows, sample_std, seed_table

R = "experiments/results/"
RUNS = {"k_step": R + "paper_ratio_k_step/kstep.csv",
        "reach_ends": R + "paper_ratio_reach_ends/reach.csv",
        "infinite": R + "paper_ratio_1.92M/dhrl.csv",
        "figure protocol, reach_ends": R + "fig_protocol_reach_ends/fig_reach.csv",
        "figure protocol, infinite": R + "fig5_1.92M/dhrl.csv"}


def tab(run, a, m):
    return seed_table([r for r in read_rows(run) if float(r["flr_alpha"]) == a], m, run)


def ms(v):
    return f"{np.mean(v):.3f} ± {sample_std(v):.3f}"


def at(st, v, step):
    return v[st == step][0]


for name, run in RUNS.items():
    last5 = {}
    for a in (0.0, 0.01):
        print(f"== {name} alpha {a}")
        st, sd, s = tab(run, a, "success_rate")
        last5[a] = s[-5:].mean(0)
        print(" seeds", len(sd), "steps", st[0], "..", st[-1])
        print(" success at 0.48/0.96/1.44/1.92M:",
              [ms(at(st, s, x)) for x in (480000, 960000, 1440000, 1920000)])
        print(" success last-5 mean:", ms(last5[a]), " per seed", np.round(last5[a], 2),
              " evaluations with success > 0:", int((s > 0).sum()), "of", s.size)
        _, _, q = tab(run, a, "q")
        print(" Q mean at 0.24/0.48/0.96/1.92M:",
              [round(float(at(st, q, x).mean()), 1) for x in (240000, 480000, 960000, 1920000)])
        _, _, g = tab(run, a, "reward_gap")
        with warnings.catch_warnings():  # DHRL pays no FLR reward: no gap at all
            warnings.simplefilter("ignore", RuntimeWarning)
            gm = np.nanmean(g, 1)
        i = int(np.nanargmax(gm)) if np.isfinite(gm).any() and np.nanmax(gm) > 0 else None
        print(" reward gap seed-mean peak:",
              None if i is None else (round(float(gm[i]), 3), int(st[i])),
              "-> 1.92M", round(float(gm[-1]), 3))
        _, _, f = tab(run, a, "falls")
        print(" falls last-5 mean:", ms(f[-5:].mean(0)), " cumulative:", ms(f.sum(0)))
        for m in ("final_torso_z", "final_goal_distance", "random_goal_success",
                  "reach_fallen_frac", "reach_reward_upright", "dist_rank_corr", "reach_frac"):
            try:
                _, _, v = tab(run, a, m)
            except (KeyError, ValueError):
                continue
            if np.isfinite(v[-5:]).all():
                print(f" {m} last-5 mean: {ms(v[-5:].mean(0))}")
    print(f" FLR+DHRL vs DHRL, last-5 success: p = "
          f"{permutation_test(last5[0.01], last5[0.0]):.3f}")
