"""The onset numbers of docs/results.md ("What the onset of success waits for"):
PYTHONPATH=. python experiments/results/main_gpu_ant3leg_flr_dhrl/onset.py"""
import warnings

import numpy as np

from flrjax.analysis import read_rows, seed_table

RUN = "experiments/results/main_gpu_ant3leg_flr_dhrl/metrics.csv"
METRICS = ("success_rate", "goal_landmark_gap", "dist_rank_corr", "wall_edge_frac",
           "graph_nodes", "plan_found_frac", "path_to_goal")

rows = read_rows(RUN)
tabs = {m: seed_table(rows, m, RUN) for m in METRICS}
st = tabs["success_rate"][0]
with warnings.catch_warnings():  # no graph yet in the first chunks: NaN
    warnings.simplefilter("ignore", RuntimeWarning)
    print("seed means per evaluation")
    print("step " + " ".join(f"{m:>17}" for m in METRICS))
    for i, s in enumerate(st):
        print(f"{s:7d} " + " ".join(f"{np.nanmean(tabs[m][2][i]):17.3f}" for m in METRICS))


def first(v: np.ndarray, ok, steps: np.ndarray) -> int | None:
    """The first of ``steps`` where ``ok(v)`` (NaN: never), or None."""
    hit = np.where(ok(np.nan_to_num(v, nan=np.inf)))[0]
    return int(steps[hit[0]]) if len(hit) else None


_, _, s = tabs["success_rate"]
_, _, gap = tabs["goal_landmark_gap"]
_, _, nodes = tabs["graph_nodes"]
print("\nseed, first success > 0, gap < 5 m, gap < 2.5 m, landmarks at the first success")
for k in range(s.shape[1]):
    f = first(-s[:, k], lambda v: v < 0, st)
    print(k, f, first(gap[:, k], lambda v: v < 5, st), first(gap[:, k], lambda v: v < 2.5, st),
          round(float(nodes[st == f][0][k])))

# The same per seed in two runs that do not learn (docs/results.md: needed, not sufficient)
R = "experiments/results/"
for run in (R + "paper_ratio_k_step/kstep.csv", R + "fig_protocol_reach_ends/fig_reach.csv"):
    rows = read_rows(run)
    for alpha in ("0.0", "0.01"):
        point = [r for r in rows if float(r["flr_alpha"]) == float(alpha)]
        steps, _, s = seed_table(point, "success_rate", run)
        _, _, gap = seed_table(point, "goal_landmark_gap", run)
        _, _, falls = seed_table(point, "falls", run)
        print(f"\n{run} alpha {alpha}: seed, first success > 0, gap < 5 m, smallest gap (m), "
              "last-5 success, last-5 falls")
        for k in range(s.shape[1]):
            print(k, first(-s[:, k], lambda v: v < 0, steps),
                  first(gap[:, k], lambda v: v < 5, steps),
                  round(float(np.nanmin(gap[:, k])), 1), round(float(s[-5:, k].mean()), 2),
                  round(float(falls[-5:, k].mean()), 1))
