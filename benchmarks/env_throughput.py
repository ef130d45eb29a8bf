"""Env-steps/s of flrjax's MJX ant mazes against raw ``mjx.step`` on the same model.

For each batch size, three jitted functions run ``--steps`` env steps in one ``lax.scan``:
- ``env``: ``vmap(env.step)`` (action in, observation and info out);
- ``raw``: ``vmap(mjx.step)`` on the same model and data, ``frame_skip`` times per env step;
and the ratio env/raw is the env's overhead (target: within 10%). With ``--brax`` it also times
brax's own ``envs.get_environment('ant', backend='mjx')`` at two batch sizes, scanned and
driven from a Python loop (one jitted ``step`` call per env step), to show where its cost
comes from.

    python benchmarks/env_throughput.py --env ant4leg --out benchmarks/results/env_throughput.json
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from flrjax import envs


def _time(fn: Callable, arg, repeats: int) -> tuple[float, float]:
    """(compile + first run seconds, median seconds of ``repeats`` timed runs)."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn(arg))
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(arg))
        times.append(time.perf_counter() - t0)
    return first, sorted(times)[len(times) // 2]


def bench_env(env, batch: int, steps: int, repeats: int, key: jax.Array) -> dict:
    """Time env.step and raw mjx.step (x frame_skip), both scanned, at one batch size."""
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(key, batch))
    actions = jax.random.uniform(key, (batch, env.action_size), minval=-1.0, maxval=1.0)
    frame_skip = env.config.frame_skip

    @jax.jit
    def run_env(s):
        def f(s, _):
            return jax.vmap(env.step)(s, actions), None

        return jax.lax.scan(f, s, None, length=steps)[0].obs

    @jax.jit
    def run_raw(d):
        d = d.replace(ctrl=actions)

        def f(d, _):
            return jax.vmap(mjx.step, in_axes=(None, 0))(env.sys, d), None

        return jax.lax.scan(f, d, None, length=steps * frame_skip)[0].qpos

    c_env, t_env = _time(run_env, states, repeats)
    c_raw, t_raw = _time(run_raw, states.pipeline_state, repeats)
    return {
        "batch": batch,
        "env_steps_per_s": batch * steps / t_env,
        "raw_steps_per_s": batch * steps / t_raw,
        "env_ms_per_step": 1e3 * t_env / steps,
        "raw_ms_per_step": 1e3 * t_raw / steps,
        "ratio_env_over_raw": t_raw / t_env,
        "compile_s_env": c_env,
        "compile_s_raw": c_raw,
    }


def bench_loop(step: Callable, state, action, steps: int) -> float:
    """Milliseconds per env step when a Python loop calls a jitted step once per env step."""
    state = jax.block_until_ready(step(state, action))
    t0 = time.perf_counter()
    for _ in range(steps):
        state = step(state, action)
    jax.block_until_ready(state)
    return 1e3 * (time.perf_counter() - t0) / steps


def bench_brax_and_loops(env, batches: list[int], steps: int, repeats: int, key) -> list[dict]:
    """brax's mjx ant (scanned and Python-loop driven) next to ours driven the same two ways."""
    from brax import envs as brax_envs

    brax_ant = brax_envs.get_environment("ant", backend="mjx")
    rows = []
    for name, e in (("brax_ant", brax_ant), ("flrjax_" + env.__class__.__name__, env)):
        for batch in batches:
            s = jax.jit(jax.vmap(e.reset))(jax.random.split(key, batch))
            a = jnp.zeros((batch, e.action_size))
            vstep = jax.vmap(e.step)

            @jax.jit
            def run(s, vstep=vstep, a=a):
                return jax.lax.scan(lambda s, _: (vstep(s, a), None), s, None, length=steps)[0].obs

            _, t_scan = _time(run, s, repeats)
            t_loop = bench_loop(jax.jit(vstep), s, a, steps)
            rows.append({"env": name, "batch": batch, "scan_ms_per_step": 1e3 * t_scan / steps,
                         "loop_ms_per_step": t_loop})
    return rows


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg", choices=[n for n in envs.names() if "ant" in n])
    p.add_argument("--batches", default="1,16,256,1024,4096,16384")
    p.add_argument("--steps", type=int, default=50, help="env steps per timed scan")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--brax", action="store_true", help="also time brax's mjx ant")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="env option override, e.g. --set walls_collide_with=torso")
    p.add_argument("--out", default=None, help="write the results as JSON here")
    args = p.parse_args(argv)

    overrides = {}
    for kv in args.set:
        k, v = kv.split("=", 1)
        overrides[k] = int(v) if v.lstrip("-").isdigit() else v
    env = envs.make(args.env, **overrides)
    key = jax.random.PRNGKey(0)
    batches = [int(b) for b in args.batches.split(",")]
    rows = []
    for b in batches:
        rows.append(bench_env(env, b, args.steps, args.repeats, key))
        print({k: round(v, 4) if isinstance(v, float) else v for k, v in rows[-1].items()},
              flush=True)
    extra = bench_brax_and_loops(env, [1, 1024], args.steps, args.repeats, key) if args.brax else []
    result = {
        "benchmark": "env_throughput",
        "command": "python " + " ".join(sys.argv),
        "device": str(jax.devices()[0].device_kind),
        "platform": jax.default_backend(),
        "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__,
                     "python": platform.python_version()},
        "env": args.env,
        "overrides": overrides,
        "contacts": int(mjx.make_data(env.mj_model)._impl.ncon),
        "frame_skip": env.config.frame_skip,
        "model": {"nq": env.mj_model.nq, "nv": env.mj_model.nv, "ngeom": env.mj_model.ngeom,
                  "solver_iterations": env.spec.solver_iterations,
                  "ls_iterations": env.spec.ls_iterations, "integrator": env.spec.integrator},
        "rows": rows,
        "brax_comparison": extra,
    }
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    print(f"\n{args.env} {overrides or ''} on {result['device']} ({args.steps} env steps per "
          f"scan, frame_skip {env.config.frame_skip}, {result['contacts']} contacts)")
    print(f"{'batch':>6} {'env steps/s':>13} {'raw steps/s':>13} {'env/raw':>8} {'env ms':>8}")
    for r in rows:
        print(f"{r['batch']:>6} {r['env_steps_per_s']:>13,.0f} {r['raw_steps_per_s']:>13,.0f} "
              f"{r['ratio_env_over_raw']:>8.3f} {r['env_ms_per_step']:>8.3f}")
    for r in extra:
        print(f"{r['env']:>24} batch {r['batch']:>5}: scanned {r['scan_ms_per_step']:.3f} ms/step,"
              f" python loop {r['loop_ms_per_step']:.3f} ms/step")


if __name__ == "__main__":
    main()
