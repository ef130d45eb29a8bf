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


def first(v: np.ndarray, ok) -> int | None:
    hit = np.where(ok(np.nan_to_num(v, nan=np.inf)))[0]
    return int(st[hit[0]]) if len(hit) else None


_, _, s = tabs["success_rate"]
_, _, gap = tabs["goal_landmark_gap"]
_, _, nodes = tabs["graph_nodes"]
print("\nseed, first success > 0, gap < 5 m, gap < 2.5 m, landmarks at the first success")
for k in range(s.shape[1]):
    f = first(-s[:, k], lambda v: v < 0)
    print(k, f, first(gap[:, k], lambda v: v < 5), first(gap[:, k], lambda v: v < 2.5),
          round(float(nodes[st == f][0][k])))
