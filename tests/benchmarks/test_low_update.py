"""low_update: one low-level update per seed, timed, with its FLOP count."""

import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import low_update  # noqa: E402


def test_flop_count_by_hand():
    # actor 4 -> 8 -> 1, critic 5 -> 8 -> 1: forward 2 * (32 + 8) and 2 * (40 + 8) FLOPs
    f = low_update.update_flops(obs=2, goal=2, action=1, hidden=(8,), batch=10, reach=0.5,
                                candidates=3, flr=True)
    f_a, f_c = 80, 96
    assert f["critic_main"] == f["critic_g"] == 10 * (6 * f_c + f_a + 2 * f_c)
    assert f["flr_values"] == 0.5 * 10 * 3 * (f_a + 2 * f_c)
    assert f["actor_half"] == 0.5 * 10 * (3 * f_a + 2 * f_c)
    assert f["total"] == f["critic_main"] + f["critic_g"] + f["flr_values"] + f["actor_half"]
    assert low_update.update_flops(obs=2, goal=2, action=1, hidden=(8,), batch=10, reach=0.5,
                                   candidates=3, flr=False)["flr_values"] == 0


def test_variants_are_timed(tmp_path):
    """In its own process, as the other benchmarks that compile several programs."""
    out = str(tmp_path / "low.json")
    subprocess.run([sys.executable, low_update.__file__, "--env", "point3leg", "--seeds", "2",
                    "--batch-size", "32", "--hidden", "16", "--updates", "2", "--repeats",
                    "1", "--variants", "dhrl,bf16-m4-c0", "--out", out], check=True,
                   capture_output=True, timeout=600)
    with open(out) as f:
        v = json.load(f)["variants"]
    assert v["dhrl"]["ms_per_update"] > 0 and v["bf16-m4-c0"]["ms_per_update"] > 0
    assert v["dhrl"]["gflop_per_update"]["flr_values"] == 0
    assert v["bf16-m4-c0"]["gflop_per_update"]["flr_values"] > 0
