"""The figure scripts end to end at a CPU budget: runs, CSVs, plots."""

import csv
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import figures  # noqa: E402
import plot_curves  # noqa: E402

TINY = ("--preset quick --num-envs 4 --initial-episodes 4 --episodes-per-chunk 1 --hidden 16 "
        "--batch-size 32 --graph-start-steps 0 --max-landmarks 8 --landmark-sample 64")


def test_fig5_subset_runs_and_plots(tmp_path):
    out = str(tmp_path)
    figures.main(["fig5", "--env", "point3leg", "--seeds", "2", "--steps", "800", "--extra",
                  TINY, "--only", "dhrl,next_goal", "--out", out])
    for name in ("dhrl", "next_goal"):
        with open(os.path.join(out, f"{name}.csv")) as f:
            rows = list(csv.DictReader(f))
        assert [int(r["step"]) for r in rows] == [400, 400, 800, 800]
    runs = json.load(open(os.path.join(out, "grid.json")))
    assert [r["run"] for r in runs] == ["dhrl", "next_goal"]
    assert runs[1]["config"]["flr_next"] == "goal" and runs[1]["config"]["env"] == "point3leg"
    for metric in ("success_rate", "falls", "reward_gap"):
        assert os.path.getsize(os.path.join(out, f"fig5_{metric}.png")) > 1000
    # falls are plotted cumulatively, per seed
    steps, mean, _ = plot_curves.curve(os.path.join(out, "dhrl.csv"), "falls", cumulative=True)
    assert list(steps) == [400, 800] and np.all(np.diff(mean) >= 0)
