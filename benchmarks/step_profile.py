"""Where one training iteration's device time goes, by kernel group, and what compiling it costs.

Builds the training chunk of one config (by default the tripod figure runs' FLR+DHRL protocol,
DHRL as the alpha = 0 sweep point: 2 x 5 runs of 16 envs, 0.25 updates per env step), then
1. compiles it once per XLA option set (``--compile-options``) and times each compile and the
   chunk it gives (fastest of two calls after a first one);
2. traces one chunk call with ``jax.profiler`` and sums the GPU kernels' time per group. A
   kernel's group is the innermost named scope of the HLO instruction that launched it (the
   trainer marks ``physics``, ``act``, ``replay_insert``, ``her_sample``, ``flr_values``,
   ``critic_main``, ``critic_g``, ``target_update``, ``actor_update``, ``high_level``, ``plan``,
   ``graph_build``; gradients carry their scope inside ``transpose(jvp(...))``); kernels of
   no such scope are ``other``. The traced executable is compiled with XLA's command buffers
   off (``xla_gpu_enable_command_buffer=""``): a command buffer (a CUDA graph) shows in the
   trace as one event, so its kernels could not be told apart. Its ms per iteration is
   reported beside the default's.

Device busy time below the wall time is launch latency and host synchronisation (e.g. a while
loop's trip test). The graph is rebuilt every episode round here (the reference: every 9,000
env steps), which overstates ``graph_build``; it is reported apart.

    python benchmarks/step_profile.py --out benchmarks/results/step_profile/h100.json
"""

from __future__ import annotations

import argparse
import glob
import gzip
import json
import os
import re
import tempfile
import time
from collections import defaultdict

import jax
import jax.numpy as jnp

from flrjax import config, metrics_io, networks, runner, validation
from flrjax.agents.gc_td3 import fused_value
from flrjax.algos.common import train_precision

#: The trainer's named scopes, innermost wins (flrjax/algos/dhrl.py, agents/gc_td3/learner.py, ...).
GROUPS = ("flr_values", "critic_main", "critic_g", "target_update", "actor_update", "her_sample",
          "high_level", "plan", "graph_build", "physics", "act", "replay_insert")
#: A group name as a whole word of one op_name part (``transpose(jvp(critic_main))`` included).
_GROUP_RE = re.compile(r"\b(" + "|".join(GROUPS) + r")\b")
#: XLA's default command buffer types (xla/debug_options_flags.cc).
DEFAULT_COMMAND_BUFFERS = ("FUSION", "CUBLAS", "CUBLASLT", "CUSTOM_CALL", "CUDNN",
                           "DYNAMIC_SLICE_FUSION")
#: --compile-options presets: XLA debug options passed to ``Lowered.compile`` over the
#: trainer's own (``runner.COMPILER_OPTIONS``); "+" joins presets. Compiles in one process
#: share XLA's autotuning results: only the first is cold.
OPTION_SETS = {
    "default": {},
    "autotune0": {"xla_gpu_autotune_level": 0},
    # still autotunes, without filling the candidates' buffers with data or checking their
    # results: for the compile time
    "autotune1": {"xla_gpu_autotune_level": 1},
    "no_triton_gemm": {"xla_gpu_enable_triton_gemm": False},
    # loops and branches inside the CUDA graphs too (XLA's default list plus WHILE and
    # CONDITIONAL: a compile option replaces the list, it takes no "+"), so that a while loop's
    # trip test does not go through the host
    "loop_command_buffers": {"xla_gpu_enable_command_buffer": ",".join(DEFAULT_COMMAND_BUFFERS
                                                                       + ("WHILE", "CONDITIONAL"))},
    # a command buffer's kernels ordered by their buffers' dependencies only, so that
    # independent small kernels may run at the same time: the trainer's default now
    # (runner.COMPILER_OPTIONS), so "default" includes it
    "concurrent": {"xla_gpu_command_buffer_scheduling_mode": "CONCURRENT"},
    # XLA's own default: a command buffer's kernels in the schedule's order
    "serial": {"xla_gpu_command_buffer_scheduling_mode": "LHS"},
    # a CUDA graph for every run of kernels, however short (XLA's default: 5 at least)
    "min_graph1": {"xla_gpu_graph_min_graph_size": 1},
    # the latency-hiding scheduler orders the kernels (XLA's default: off)
    "lhs_scheduler": {"xla_gpu_enable_latency_hiding_scheduler": True},
    # scatters without atomics: the same input gives the same output, to compare options
    "deterministic": {"xla_gpu_deterministic_ops": True},
    # loops of known trip count unrolled inside a command buffer
    "unroll": {"xla_gpu_command_buffer_unroll_loops": True},
}


def compile_options(preset: str) -> dict:
    """The XLA options of a ``--compile-options`` entry (presets joined by "+")."""
    options = {}
    for name in preset.split("+"):
        options.update(OPTION_SETS[name])
    return options


#: Added to the traced executable's options: every kernel its own trace event.
NO_COMMAND_BUFFERS = {"xla_gpu_enable_command_buffer": ""}


def profile_config(args: argparse.Namespace) -> config.TrainConfig:
    """The chunk timed: one episode round of ``--episode-length`` steps per chunk, learning
    from the first round (no random phase), the graph rebuilt every round."""
    cfg = config.make(dict(
        env=args.env, algo=args.algo, seeds=args.seeds, num_envs=args.num_envs,
        steps=args.num_envs * args.episode_length, updates_per_step=args.updates_per_step,
        episodes_per_chunk=1, batch_size=args.batch_size, hidden=args.hidden,
        buffer_episodes=max(2 * args.num_envs, 50), initial_episodes=0,
        episode_length=args.episode_length, graph_start_steps=0,
        graph_every_steps=args.num_envs * args.episode_length,
        max_landmarks=args.max_landmarks, landmark_sample=args.landmark_sample, devices=1))
    takes = config.run_flags(cfg)
    if "flr_alpha" in takes:
        alphas = tuple(float(a) for a in args.flr_alpha.split(","))
        cfg = cfg.replace(flr_alpha=alphas if len(alphas) > 1 else alphas[0],
                          flr_candidates=args.flr_candidates, flr_precision=args.flr_precision,
                          flr_value_chunk=args.value_chunk)
    if "subgoal_test_precision" in takes:
        cfg = cfg.replace(subgoal_test_precision=args.subgoal_test_precision)
    if "value_kernel" in takes:
        cfg = cfg.replace(value_kernel=args.value_kernel)
    # the trainer's default resolved here, so that the result's config names it
    cfg = cfg.replace(train_precision=args.train_precision or train_precision(cfg))
    validation.validate(cfg)
    return cfg


def scope_of_instructions(hlo_text: str) -> dict[str, str]:
    """HLO instruction name -> its group, from the ``op_name`` metadata of the optimised HLO
    (a fusion carries the metadata of its root)."""
    out = {}
    pattern = re.compile(r"^\s*(?:ROOT )?%?([\w.\-]+) = .*?op_name=\"([^\"]*)\"")
    for line in hlo_text.splitlines():
        m = pattern.match(line)
        if not m:
            continue
        found = [g for p in m.group(2).split("/") for g in _GROUP_RE.findall(p)]
        out[m.group(1)] = found[-1] if found else "other"
    return out


def device_kernel_times(trace_dir: str) -> tuple[dict[str, float], dict[str, int], float]:
    """(microseconds per kernel's HLO op, kernel count per op, microseconds of all device
    events) from the perfetto trace ``jax.profiler`` wrote into ``trace_dir``."""
    path = sorted(glob.glob(os.path.join(trace_dir, "**", "perfetto_trace.json.gz"),
                            recursive=True))[-1]
    with gzip.open(path) as f:
        data = json.load(f)
    events = data["traceEvents"] if isinstance(data, dict) else data
    gpu_pids = {e["pid"] for e in events if e.get("ph") == "M" and e.get("name") ==
                "process_name" and "GPU" in str(e.get("args", {}).get("name", ""))}
    per_op: dict[str, float] = defaultdict(float)
    count: dict[str, int] = defaultdict(int)
    total = 0.0
    for e in events:
        if e.get("ph") != "X":
            continue
        # On the CPU (tests) the thunks carry the same hlo_op argument.
        if e.get("pid") not in gpu_pids if gpu_pids else "hlo_op" not in (e.get("args") or {}):
            continue
        dur = float(e.get("dur", 0.0))
        total += dur
        op = (e.get("args") or {}).get("hlo_op", e.get("name", "?"))
        per_op[op] += dur
        count[op] += 1
    return per_op, count, total


def max_abs_diff(a, b) -> float:
    """Largest absolute difference between two pytrees' float leaves (NaNs in the same places
    count as equal): the same chunk input through two compiles of one program."""
    diffs = [jnp.max(jnp.abs(jnp.where(jnp.isnan(x) & jnp.isnan(y), 0.0, x - y)))
             for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
             if jnp.issubdtype(x.dtype, jnp.floating) and x.size]
    return float(max(diffs, default=0.0))


def time_calls(chunk, carry, iters: int, metrics: bool = False):
    """(carry, ms per iteration: the fastest of two calls after an untimed first one[,
    the last call's metrics])."""
    times = []
    for i in range(3):
        t0 = time.perf_counter()
        carry, m = chunk(carry, jnp.int32(i))
        jax.block_until_ready(m)
        times.append(time.perf_counter() - t0)
    ms = 1e3 * min(times[1:]) / iters
    return (carry, ms, m) if metrics else (carry, ms)


def profile_chunk(chunk, carry, iters: int, hlo_text: str) -> dict:
    """Trace one call of the compiled ``chunk`` and group its device time per iteration."""
    with tempfile.TemporaryDirectory() as d:
        jax.profiler.start_trace(d, create_perfetto_trace=True)
        t0 = time.perf_counter()
        carry, m = chunk(carry, jnp.int32(100))
        jax.block_until_ready(m)
        wall = time.perf_counter() - t0
        jax.profiler.stop_trace()
        per_op, count, total = device_kernel_times(d)
    scope = scope_of_instructions(hlo_text)
    groups: dict[str, float] = defaultdict(float)
    kernels: dict[str, int] = defaultdict(int)
    for op, us in per_op.items():
        g = scope.get(op, "unattributed")
        groups[g] += us
        kernels[g] += count[op]
    ms = {g: groups[g] / 1e3 / iters for g in sorted(groups, key=groups.get, reverse=True)}
    return {"wall_ms_per_iter": 1e3 * wall / iters,  # under the profiler
            "device_busy_ms_per_iter": total / 1e3 / iters,
            "group_ms_per_iter": ms,
            "kernels_per_iter": {g: kernels[g] / iters for g in ms},
            "top_ops": sorted(((op, us / 1e3 / iters) for op, us in per_op.items()),
                              key=lambda x: -x[1])[:25],
            # where a group's kernel count comes from: its ops with the most kernels per
            # iteration, each [op, kernels per iteration, ms per iteration]
            "group_top_ops": {g: sorted(([op, count[op] / iters, per_op[op] / 1e3 / iters]
                                         for op in per_op if scope.get(op, "unattributed") == g),
                                        key=lambda x: (-x[1], -x[2]))[:12] for g in ms}}, carry


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant3leg")
    p.add_argument("--algo", default="flr_dhrl")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--num-envs", type=int, default=16)
    p.add_argument("--updates-per-step", type=float, default=0.25)
    p.add_argument("--batch-size", type=int, default=1024)
    p.add_argument("--episode-length", type=int, default=80)
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--max-landmarks", type=int, default=None, help="default: the env's")
    p.add_argument("--landmark-sample", type=int, default=None, help="default: the env's")
    p.add_argument("--flr-alpha", default="0,0.01", help="comma-separated: a sweep")
    p.add_argument("--flr-candidates", type=int, default=16)
    p.add_argument("--flr-precision", default=None, choices=networks.PRECISIONS)
    p.add_argument("--value-chunk", type=int, default=None)
    p.add_argument("--value-kernel", default=None, choices=fused_value.KERNELS)
    p.add_argument("--subgoal-test-precision", default=None, choices=networks.PRECISIONS)
    p.add_argument("--train-precision", default=None, choices=networks.PRECISIONS,
                   help="default: the trainer's (bfloat16 for dhrl and flr_dhrl on a GPU)")
    p.add_argument("--compile-options", default="default",
                   help=f"comma-separated entries, each one or more presets of "
                        f"{', '.join(OPTION_SETS)} joined by '+'; the first entry is the "
                        "traced one's")
    p.add_argument("--no-trace", action="store_true", help="compile and time only")
    p.add_argument("--hlo-out", default=None,
                   help="write the traced executable's optimised HLO here, gzipped (to read "
                        "its fusions)")
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    cfg = profile_config(args)
    iters = args.episode_length
    t0 = time.perf_counter()
    init, chunk, _ = runner.build(cfg)
    carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
    jax.block_until_ready(carry)
    init_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    lowered = chunk.lower(carry, jnp.int32(0))
    lower_s = time.perf_counter() - t0
    result = {"benchmark": "step_profile", **metrics_io.provenance(),
              "device": jax.devices()[0].device_kind,
              "jax": jax.__version__, "config": metrics_io.config_dict(cfg), "runs": cfg.runs,
              "iterations_per_chunk": iters, "init_s": init_s, "lower_s": lower_s,
              "compile": {}}
    start = jax.tree.map(jnp.copy, carry)  # every option's first call starts here (donated)
    first_out = None
    for name in args.compile_options.split(","):
        t0 = time.perf_counter()
        try:
            c = lowered.compile(compiler_options=compile_options(name))
        except Exception as e:  # an option this XLA does not take: say so, time the others
            result["compile"][name] = {"error": str(e).splitlines()[0][:300]}
            print(f"{name:<28} failed: {result['compile'][name]['error']}", flush=True)
            continue
        compile_s = time.perf_counter() - t0
        out = c(jax.tree.map(jnp.copy, start), jnp.int32(0))
        first_out = out if first_out is None else first_out
        carry, ms, m = time_calls(c, carry, iters, metrics=True)
        result["compile"][name] = {"compile_s": compile_s, "ms_per_iter": ms,
                                   "reach_frac": float(jnp.nanmean(m["stats/reach_frac"]))
                                   if "stats/reach_frac" in m else None,
                                   "max_abs_diff_vs_first": max_abs_diff(out, first_out)}
        del out
        ms = result["compile"][name]["ms_per_iter"]
        print(f"{name:<28} compile {compile_s:7.1f} s   {ms:7.2f} ms/iter   max |diff| vs "
              f"first {result['compile'][name]['max_abs_diff_vs_first']:.3g}", flush=True)
    if not args.no_trace:
        traced = lowered.compile(compiler_options={
            **compile_options(args.compile_options.split(",")[0]), **NO_COMMAND_BUFFERS})
        carry, ms = time_calls(traced, carry, iters)
        hlo = traced.as_text()
        if args.hlo_out:
            with gzip.open(args.hlo_out, "wt") as f:
                f.write(hlo)
        prof, carry = profile_chunk(traced, carry, iters, hlo)
        prof["no_command_buffers_ms_per_iter"] = ms
        result["profile"] = prof
    if args.out:
        metrics_io.write_json(args.out, result)
    print(f"{cfg.algo} {cfg.env}, {cfg.runs} runs x {cfg.num_envs} envs, "
          f"{cfg.updates_per_iter} updates per iteration, {result['device']}")
    print(f"init (compile included) {init_s:.1f} s, lowering {lower_s:.1f} s")
    if "profile" in result:
        prof = result["profile"]
        print(f"traced without command buffers: device busy "
              f"{prof['device_busy_ms_per_iter']:.2f} ms/iter")
        print(f"{'group':<16}{'ms/iter':>10}{'kernels/iter':>14}")
        for g, ms in prof["group_ms_per_iter"].items():
            print(f"{g:<16}{ms:>10.3f}{prof['kernels_per_iter'][g]:>14.1f}")


if __name__ == "__main__":
    main()
