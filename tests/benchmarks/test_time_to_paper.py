"""time_to_paper reads the committed measurements and extrapolates them consistently."""

import json
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import time_to_paper  # noqa: E402


def test_extrapolation_from_committed_measurements(tmp_path):
    out = tmp_path / "t.json"
    time_to_paper.main(["--steps", "600000", "--out", str(out)])
    rows = json.loads(out.read_text())["rows"]
    assert {r["method"] for r in rows} >= {"flat", "dhrl", "flr_dhrl"}
    for r in rows:
        assert r["steps_per_s"] > 0
        assert r["extrapolated_minutes"] == pytest.approx(600_000 * r["seeds"]
                                                          / r["steps_per_s"] / 60)
    # every committed training run got past 600k steps: its measured wall time there, which
    # also pays compiles and evaluations, cannot beat the extrapolation by much
    runs = [r for r in rows if r["source"].startswith("experiments/")]
    assert len(runs) == len(time_to_paper.TRAINING_RUNS)
    for r in runs:
        assert r["measured_minutes"] > 0.9 * r["extrapolated_minutes"]
