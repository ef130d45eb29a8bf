"""flr_cost: the FLR of one batch, full and with each chunk size, at a tiny size."""

import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import flr_cost  # noqa: E402


def test_every_way_is_timed_at_each_reaching_fraction(tmp_path):
    out = str(tmp_path / "flr.json")
    flr_cost.main(["--batch", "64", "--candidates", "4", "--hidden", "16", "--chunks", "8,64",
                   "--fractions", "0.0,0.5,1.0", "--out", out])  # main checks equal rewards
    with open(out) as f:
        rows = json.load(f)["rows"]
    assert [r["reach_fraction"] for r in rows][::2] == [0.0, 1.0]
    assert 0.3 < rows[1]["reach_fraction"] < 0.7
    assert all(r["full_ms"] > 0 for r in rows)
    assert all(sorted(r["chunked_ms"]) == ["64", "8"] and min(r["chunked_ms"].values()) > 0
               for r in rows)
