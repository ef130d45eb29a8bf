"""host_loop_baseline: the Python-driven loop trains and is timed; speed-ups are per flat row."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import host_loop_baseline as hl  # noqa: E402
import train_throughput as tt  # noqa: E402


def test_host_loop_runs_and_speedups_use_flat_rows():
    cfg = tt.job_config({"env": "point4leg", "seeds": 1, "envs": 1, "protocol": "paper",
                         "measure": "flat", "episode_length": 40})
    first, steps_per_s = hl.host_loop_steps_per_s(cfg, 4)
    assert first > 0 and steps_per_s > 0
    scanned = {"rows": [
        {"seeds": 5, "envs_per_seed": 1, "protocol": "paper", "updates_per_step": 1.0,
         "flat_env_steps_per_s": 500.0},
        {"seeds": 5, "envs_per_seed": 16, "protocol": "fast", "updates_per_step": 1 / 16,
         "flr_dhrl_env_steps_per_s": 900.0}]}  # no flat row: not compared
    (row,) = hl.speedups(100.0, scanned)
    assert row["speedup"] == pytest.approx(5.0) and row["protocol"] == "paper"
