"""flr_kernel: eq. 5's candidate values by XLA and by the fused kernel, timed and compared."""

import json
import os
import subprocess
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import flr_kernel  # noqa: E402


def test_variant_names_give_the_kernel_settings():
    assert flr_kernel.variant_fn("xla") and flr_kernel.variant_fn("fused-64x4")
    with pytest.raises(SystemExit, match="unknown variant"):
        flr_kernel.variant_fn("pallas")


def test_xla_and_fused_values_are_timed_and_compared(tmp_path):
    """In its own process (it compiles a program per variant); the fused kernel runs in
    Pallas's interpreter here, its values within bf16's reach of XLA's."""
    out = str(tmp_path / "kernel.json")
    subprocess.run([sys.executable, flr_kernel.__file__, "--env", "point3leg", "--seeds", "2",
                    "--batch", "8", "--candidates", "4", "--hidden", "16",
                    "--calls-per-timing", "2", "--repeats", "1", "--configs", "16x4x1x16,32",
                    "--out", out], check=True, capture_output=True, timeout=600)
    with open(out) as f:
        result = json.load(f)
    v = result["variants"]
    assert set(v) == {"f32", "xla", "fused-16x4x1x16", "fused-32"}
    assert result["gflop_per_call"] > 0
    for name in ("fused-16x4x1x16", "fused-32"):
        assert v[name]["ms_per_call"] > 0
        assert v[name]["mean_abs_diff_vs_xla"] < 0.01 * v[name]["mean_abs_value"]
        assert v[name]["mean_abs_diff_vs_f32"] < 2 * v["xla"]["mean_abs_diff_vs_f32"]
