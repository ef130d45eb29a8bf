"""low_update: one low-level update per seed, timed, with its FLOP count."""

import json
import os
import subprocess
import sys

import pytest

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


def test_variant_names():
    base = low_update.config.TrainConfig(env="point3leg", algo="dhrl")
    for name, algo, flr_precision, train in [
            ("dhrl", "dhrl", None, "float32"), ("dhrl-train16", "dhrl", None, "bfloat16"),
            ("bf16-c0", "flr_dhrl", "bfloat16", "float32"),
            ("bf16-c0-train16", "flr_dhrl", "bfloat16", "bfloat16")]:
        cfg = low_update.variant_config(base, name)
        assert (cfg.algo, cfg.flr_precision, cfg.train_precision) == (algo, flr_precision, train)
    assert low_update.variant_config(base, "bf16-c0").flr_value_chunk == 0
    with pytest.raises(SystemExit, match="unknown variant part"):
        low_update.variant_config(base, "train16-bf16")


def test_variants_are_timed(tmp_path):
    """In its own process, as the other benchmarks that compile several programs; the FLR
    variant with bf16 updates (``-train16``), the DHRL one without."""
    out = str(tmp_path / "low.json")
    subprocess.run([sys.executable, low_update.__file__, "--env", "point3leg", "--seeds", "2",
                    "--batch-size", "32", "--hidden", "16", "--updates", "2", "--repeats",
                    "1", "--variants", "dhrl,bf16-m4-c0-train16", "--out", out], check=True,
                   capture_output=True, timeout=600)
    with open(out) as f:
        result = json.load(f)
    assert result["command"].startswith("python ") and "--variants" in result["command"]
    assert "commit" in result  # provenance (None outside a git checkout)
    v = result["variants"]
    flr = v["bf16-m4-c0-train16"]
    assert v["dhrl"]["ms_per_update"] > 0 and flr["ms_per_update"] > 0
    assert v["dhrl"]["gflop_per_update"]["flr_values"] == 0
    assert flr["gflop_per_update"]["flr_values"] > 0
