"""Eq. 5's candidate values, XLA against the fused kernel: ms, TFLOP/s and the difference.

Times ``V(s', sg')`` (the target actor and both target critics) on ``--seeds`` x ``--batch``
transitions x ``--candidates`` next subgoals, vmapped over the seeds, as the trainer's GPU
default computes it: bf16 matrix operands on the whole batch. ``xla`` is
:func:`gc_td3.value` (an XLA kernel per layer); ``fused-BxWxSxC`` is
:func:`gc_td3.fused_value.value` with B rows per kernel instance, W warps, S pipeline stages
(Triton's settings) and C-wide column chunks (parts left off: the defaults). Each call
evaluates ``--calls-per-timing`` independent inputs in one jitted scan; the fastest of
``--repeats`` timings counts.

FLOPs: 2 per multiply-add of the three networks' products (``low_update.mlp_flops``). The
difference columns compare each variant's V with XLA's bf16 one and with float32's.

    python benchmarks/flr_kernel.py --configs 64x4x1,128x8x1 --out RESULT.json
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp

from flrjax import config, metrics_io
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from low_update import PEAK_TFLOPS, mlp_flops  # noqa: E402
from update_cost import fastest_ms  # noqa: E402


def agents(key: jax.Array, seeds: int, obs: int, action: int, hidden: int
           ) -> gc_td3.AgentState:
    """``seeds`` agents whose target networks differ from the online ones and per twin."""
    cfg = gc_td3.TD3Config(hidden_sizes=(hidden,) * 3)

    def one(k):
        k_init, k_noise = jax.random.split(k)
        state = gc_td3.init(k_init, obs, 2, action, cfg)
        leaves, tree = jax.tree.flatten(state.critic.target_params)
        noise = jax.random.split(k_noise, len(leaves))
        jitter = [x * (1 + 0.2 * jax.random.normal(n, x.shape)) for n, x in zip(noise, leaves,
                                                                                strict=True)]
        return state.replace(critic=state.critic.replace(
            target_params=jax.tree.unflatten(tree, jitter)))

    return jax.vmap(one)(jax.random.split(key, seeds))


def inputs(key: jax.Array, calls: int, seeds: int, batch: int, candidates: int, obs: int
           ) -> tuple[jax.Array, jax.Array]:
    """``calls`` sets of next observations and candidates near them, as in the maze."""
    k_o, k_g = jax.random.split(key)
    next_obs = jax.random.normal(k_o, (calls, seeds, batch, obs))
    next_obs = next_obs.at[..., :2].multiply(6.0)  # torso x, y spread over the room
    ring = 2.5 * jax.random.normal(k_g, (calls, seeds, batch, candidates, 2))
    return next_obs, next_obs[..., None, :2] + ring


def variant_fn(name: str):
    """``f(agent, obs, goals) -> [B, M]`` of a variant name."""
    if name == "xla":
        return lambda a, o, g: gc_td3.value(a, o, g, dot_dtype=jnp.bfloat16)
    if name == "f32":
        return lambda a, o, g: gc_td3.value(a, o, g)
    kind, _, spec = name.partition("-")
    if kind != "fused":
        raise SystemExit(f"unknown variant {name!r}")
    defaults = (fused_value.BLOCK_ROWS, fused_value.NUM_WARPS, fused_value.NUM_STAGES,
                fused_value.CHUNK_COLS)
    given = [int(x) for x in spec.split("x")] if spec else []
    block, warps, stages, cols = (*given, *defaults[len(given):])
    settings = fused_value.KernelSettings(block_rows=block, num_warps=warps, num_stages=stages,
                                          chunk_cols=cols)
    return lambda a, o, g: fused_value.value(a, o, g, settings=settings)


def scanned(fn):
    """jit of: every call's values, the seeds vmapped, the calls scanned."""
    per_seed = jax.vmap(fn)

    def run(agents, obs, goals):
        return jax.lax.map(lambda xs: per_seed(agents, *xs), (obs, goals))

    return jax.jit(run)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant3leg")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument("--candidates", type=int, default=16)
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--calls-per-timing", type=int, default=20)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--configs", default="64x4x1",
                   help="fused kernel settings BLOCKxWARPSxSTAGESxCOLS, comma-separated")
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    env = config.make_env(config.TrainConfig(env=args.env, algo="dhrl"))
    o, a = env.observation_size, env.action_size
    agent = agents(jax.random.PRNGKey(0), args.seeds, o, a, args.hidden)
    sets = [inputs(jax.random.PRNGKey(1 + i), args.calls_per_timing, args.seeds, args.batch,
                   args.candidates, o) for i in range(args.repeats + 1)]
    h = (args.hidden,) * 3
    flops = args.seeds * args.batch * args.candidates * (
        mlp_flops((o + 2, *h, a)) + 2 * mlp_flops((o + 2 + a, *h, 1)))
    names = ["f32", "xla"] + ["fused-" + c for c in args.configs.split(",")]
    values = {}
    result = {"benchmark": "flr_kernel", **metrics_io.provenance(),
              "device": jax.devices()[0].device_kind,
              "backend": jax.default_backend(), "jax": jax.__version__, "env": args.env,
              "seeds": args.seeds, "batch": args.batch, "candidates": args.candidates,
              "hidden": args.hidden, "gflop_per_call": flops / 1e9,
              "peak_tflops_datasheet": PEAK_TFLOPS, "variants": {}}
    for name in names:
        f = scanned(variant_fn(name))
        try:
            ms = fastest_ms(lambda i, f=f: f(agent, *sets[i]), args.repeats)
        except Exception as e:  # a Triton setting that does not compile: report, go on
            result["variants"][name] = {"error": f"{type(e).__name__}: {str(e)[:300]}"}
            print(f"{name:<18} failed: {type(e).__name__}", flush=True)
            continue
        values[name] = f(agent, *sets[0])
        ms /= args.calls_per_timing
        r = {"ms_per_call": ms, "tflops": flops / ms / 1e9}
        for ref in ("xla", "f32"):
            if ref in values and name != ref:
                d = jnp.abs(values[name] - values[ref])
                r[f"max_abs_diff_vs_{ref}"] = float(d.max())
                r[f"mean_abs_diff_vs_{ref}"] = float(d.mean())
        r["mean_abs_value"] = float(jnp.abs(values[name]).mean())
        result["variants"][name] = r
    print(f"{'variant':<18}{'ms':>8}{'TFLOP/s':>9}{'mean|d| xla':>13}{'mean|d| f32':>13}")
    for name, r in result["variants"].items():
        if "error" in r:
            print(f"{name:<18} {r['error'][:60]}")
            continue
        print(f"{name:<18}{r['ms_per_call']:8.3f}{r['tflops']:9.1f}"
              f"{r.get('mean_abs_diff_vs_xla', 0):13.2e}{r.get('mean_abs_diff_vs_f32', 0):13.2e}")
    if args.out:
        metrics_io.write_json(args.out, result)


if __name__ == "__main__":
    main()
