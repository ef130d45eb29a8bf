"""step_profile: compile, time and trace one tiny training chunk, kernels grouped by scope."""

import gzip
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import step_profile  # noqa: E402


def test_scopes_are_read_from_op_names_gradients_included():
    hlo = "\n".join([
        '  %fusion.1 = f32[8] fusion(%a), metadata={op_name="jit(chunk)/vmap(scan)/'
        'critic_main/dot_general"}',
        '  ROOT %gemm.2 = f32[8] custom-call(%b), metadata={op_name="jit(chunk)/'
        'transpose(jvp(critic_g))/dot_general"}',
        '  %f.3 = f32[8] fusion(%c), metadata={op_name="jit(chunk)/high_level/critic_main/'
        'flr_values/mul"}',
        '  %f.4 = f32[8] fusion(%c), metadata={op_name="jit(chunk)/physics_x/mul"}',
    ])
    assert step_profile.scope_of_instructions(hlo) == {
        "fusion.1": "critic_main", "gemm.2": "critic_g", "f.3": "flr_values", "f.4": "other"}


def test_tiny_chunk_is_compiled_timed_and_its_kernels_grouped(tmp_path):
    """In its own process: the profiler's state stays out of the test session."""
    out = str(tmp_path / "profile.json")
    subprocess.run([sys.executable, step_profile.__file__, "--env", "point3leg", "--seeds",
                    "1", "--num-envs", "2", "--batch-size", "32", "--episode-length", "20",
                    "--hidden", "16", "--max-landmarks", "8", "--landmark-sample", "64",
                    "--updates-per-step", "1", "--flr-candidates", "4", "--out", out,
                    "--compile-options", "default,loop_command_buffers+concurrent+unroll",
                    "--hlo-out", str(tmp_path / "hlo.txt.gz")],
                   check=True, capture_output=True, timeout=600)
    with open(out) as f:
        result = json.load(f)
    assert result["runs"] == 2  # DHRL (alpha 0) and FLR+DHRL, one seed each
    assert result["config"]["train_precision"] == "float32"  # the trainer's CPU default, named
    assert result["compile"]["default"]["compile_s"] > 0
    assert result["compile"]["default"]["ms_per_iter"] > 0
    # GPU-only options: the CPU compiles them and runs the same chunk to the same numbers
    assert result["compile"]["loop_command_buffers+concurrent+unroll"]["ms_per_iter"] > 0
    for name in result["compile"]:
        assert result["compile"][name]["max_abs_diff_vs_first"] == 0.0
    with gzip.open(tmp_path / "hlo.txt.gz", "rt") as f:
        assert "flr_values" in f.read()  # the optimised HLO keeps the scopes' op names
    groups = result["profile"]["group_ms_per_iter"]
    for g in ("critic_main", "critic_g", "flr_values", "actor_update", "physics"):
        assert groups.get(g, 0) > 0, (g, groups)
    assert abs(sum(groups.values()) - result["profile"]["device_busy_ms_per_iter"]) < 1e-6
    # each group's listed ops: its own, with the kernel counts the group's total is made of
    top = result["profile"]["group_top_ops"]
    assert set(top) == set(groups)
    for g, ops in top.items():
        counts = [c for _, c, _ in ops]
        assert counts == sorted(counts, reverse=True) and len(ops) <= 12
        assert sum(counts) <= result["profile"]["kernels_per_iter"][g] + 1e-9
        assert sum(ms for _, _, ms in ops) <= groups[g] + 1e-9


def test_max_abs_diff_reads_float_leaves_and_matches_nans():
    import jax.numpy as jnp
    a = {"x": jnp.array([1.0, jnp.nan, 3.0]), "n": jnp.array([1, 2])}
    b = {"x": jnp.array([1.5, jnp.nan, 3.0]), "n": jnp.array([7, 2])}
    assert step_profile.max_abs_diff(a, b) == 0.5
    assert step_profile.max_abs_diff(a, a) == 0.0


def test_compile_option_presets_join_with_plus():
    assert step_profile.compile_options("autotune1+no_triton_gemm") == {
        "xla_gpu_autotune_level": 1, "xla_gpu_enable_triton_gemm": False}
    assert step_profile.compile_options("default") == {}
    import jax
    for name in step_profile.OPTION_SETS:  # XLA takes every preset's names and values
        jax.jit(lambda x: x + 1).lower(1.0).compile(
            compiler_options=step_profile.compile_options(name))
    loops = step_profile.compile_options("loop_command_buffers")["xla_gpu_enable_command_buffer"]
    assert "+" not in loops and {"FUSION", "WHILE", "CONDITIONAL"} <= set(loops.split(","))
