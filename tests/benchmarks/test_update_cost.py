"""update_cost: one DHRL subgoal period's updates by part, at a tiny size."""

import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import update_cost  # noqa: E402


def test_parts_are_timed_and_the_counts_are_the_periods(tmp_path):
    out = str(tmp_path / "cost.json")
    update_cost.main(["--env", "point4leg", "--batch-size", "32", "--hidden", "16",
                      "--max-landmarks", "8", "--out", out])
    with open(out) as f:
        result = json.load(f)
    assert set(result["ms_per_period"]) == {"low", "high", "high_without_testing"}
    assert all(ms > 0 for ms in result["ms_per_period"].values())
    # the point mass's period: 10 env steps, one low update each, an actor step per 2;
    # high updates: one per 10 low ones but at least one actor step's worth (2), 20% tested
    assert result["counts"] == {"env_steps": 10, "low_critic": 10, "low_actor": 5,
                                "high_critic": 2, "high_actor": 1, "landmarks": 8,
                                "tested_subgoals": 6}
