"""The figure scripts end to end at a CPU budget: runs, CSVs, plots, a time-limited grid."""

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


def _steps(path):
    with open(path) as f:
        return [int(r["step"]) for r in csv.DictReader(f)]


def test_fig5_subset_runs_continues_after_a_time_limit_and_plots(tmp_path, capsys):
    out, runs = str(tmp_path / "fig"), str(tmp_path / "runs")
    argv = ["fig5", "--env", "point3leg", "--seeds", "2", "--steps", "800", "--extra", TINY,
            "--only", "dhrl,alpha", "--out", out, "--runs", runs]
    # a limit shorter than a chunk (compiling alone takes longer): dhrl stops after its first
    # chunk, checkpointed, and alpha (a sweep of two values) does not start
    figures.main([*argv, "--time-limit", "3"])
    assert _steps(os.path.join(out, "dhrl.csv")) == [400, 400]
    assert not os.path.exists(os.path.join(out, "alpha.csv"))
    assert os.listdir(os.path.join(runs, "dhrl", "checkpoints")) == ["chunk_000001"]
    figures.main(argv)  # the same command again resumes dhrl, then runs alpha
    assert _steps(os.path.join(out, "dhrl.csv")) == [400, 400, 800, 800]
    assert _steps(os.path.join(out, "alpha.csv")) == [400] * 4 + [800] * 4
    assert plot_curves.sweep_values(os.path.join(out, "alpha.csv")) == [
        {"flr_alpha": "0.001"}, {"flr_alpha": "0.1"}]
    grid = json.load(open(os.path.join(out, "grid.json")))
    assert [(r["run"], r["steps_done"]) for r in grid] == [("dhrl", 800), ("alpha", 800)]
    assert grid[1]["config"]["flr_alpha"] == [0.001, 0.1]
    assert grid[1]["config"]["env"] == "point3leg"
    for metric in ("success_rate", "falls", "reward_gap"):
        assert os.path.getsize(os.path.join(out, f"fig5_{metric}.png")) > 1000
    # falls are plotted cumulatively, per seed
    steps, mean, _ = plot_curves.curve(os.path.join(out, "dhrl.csv"), "falls", cumulative=True)
    assert list(steps) == [400, 800] and np.all(np.diff(mean) >= 0)
    capsys.readouterr()
    figures.main(argv)  # nothing left to run
    assert capsys.readouterr().out.count("finished before, skipped") == 2
