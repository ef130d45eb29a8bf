"""pairwise_memory: the landmark distance matrices' memory, one call against row blocks."""

import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import pairwise_memory  # noqa: E402


def test_row_blocks_need_a_fraction_of_one_call_and_the_json_says_so(tmp_path):
    out = str(tmp_path / "mem.json")
    pairwise_memory.main(["--env", "ant4leg", "--seeds", "2", "--out", out])
    with open(out) as f:
        result = json.load(f)
    assert result["landmarks"] > result["rows_per_call"] and result["tested_subgoals"] == 205
    gib = result["temp_gib"]
    for name in ("graph", "subgoal_testing"):
        assert 0 < gib[f"{name}_row_blocks"] < gib[f"{name}_one_call"] / 4
