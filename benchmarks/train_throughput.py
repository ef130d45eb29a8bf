"""Env-steps/s of the full training step (act, store, HER sample, TD3 updates) against the same
chunk without updates and against raw physics, for seeds x envs-per-seed configurations.

    python benchmarks/train_throughput.py --env ant4leg --configs 1x1,5x1,5x16,50x16,5x256
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time

import jax
import jax.numpy as jnp
import mujoco

from flrjax import train

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from env_throughput import bench_env  # noqa: E402


def time_chunk(cfg: train.TrainConfig) -> tuple[float, float]:
    """(compile + first call seconds, seconds of a second call) of one training chunk."""
    init, chunk, _ = train.build(cfg)
    carry = init(jax.random.split(jax.random.PRNGKey(0), cfg.seeds))
    t0 = time.perf_counter()
    carry, m = chunk(carry, jnp.int32(0))
    jax.block_until_ready(m)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    carry, m = chunk(carry, jnp.int32(1))
    jax.block_until_ready(m)
    return first, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--configs", default="1x1,5x1,5x16,50x16,5x256", help="SEEDSxENVS,...")
    p.add_argument("--updates-per-step", type=float, default=1.0)
    p.add_argument("--episode-length", type=int, default=600)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    rows = []
    for spec in args.configs.split(","):
        seeds, num_envs = (int(x) for x in spec.split("x"))
        base = train.TrainConfig(
            env=args.env, seeds=seeds, num_envs=num_envs, steps=num_envs * args.episode_length,
            updates_per_step=args.updates_per_step, episodes_per_chunk=1, batch_size=1024,
            hidden=256, buffer_episodes=max(2 * num_envs, 50), initial_episodes=0,
            episode_length=args.episode_length)
        no_upd = dataclasses.replace(base, initial_episodes=10**9)  # random actions, no updates
        c_full, t_full = time_chunk(base)
        c_noupd, t_noupd = time_chunk(no_upd)
        env = train.make_env(base)
        # raw physics exists for the MJX envs only (the point mass has none)
        raw = (bench_env(env, seeds * num_envs, 50, 3, jax.random.PRNGKey(0))
               if hasattr(env, "sys") else {"raw_steps_per_s": float("nan"),
                                            "raw_ms_per_step": float("nan")})
        iters = args.episode_length
        row = {
            "seeds": seeds, "envs_per_seed": num_envs, "batch": seeds * num_envs,
            "updates_per_iter": base.updates_per_iter,
            "full_env_steps_per_s": seeds * num_envs * iters / t_full,
            "no_update_env_steps_per_s": seeds * num_envs * iters / t_noupd,
            "raw_physics_env_steps_per_s": raw["raw_steps_per_s"],
            "full_ms_per_iter": 1e3 * t_full / iters,
            "no_update_ms_per_iter": 1e3 * t_noupd / iters,
            "raw_physics_ms_per_iter": raw["raw_ms_per_step"],
            "compile_s": c_full - t_full,
        }
        row["updates_ms_per_iter"] = row["full_ms_per_iter"] - row["no_update_ms_per_iter"]
        rows.append(row)
        print({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
    result = {"benchmark": "train_throughput", "command": "python " + " ".join(sys.argv),
              "device": str(jax.devices()[0].device_kind),
              "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__,
                           "python": platform.python_version()},
              "env": args.env, "algo": "flat", "updates_per_step": args.updates_per_step,
              "rows": rows}
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    print(f"\n{args.env}, flat, {args.updates_per_step:g} updates per env step, "
          f"batch 1024, 3x256 MLPs, on {result['device']}")
    print(f"{'seeds x envs':>12} {'full steps/s':>13} {'no-upd steps/s':>15} "
          f"{'raw phys steps/s':>17} {'full ms/it':>10} {'phys ms/it':>10} {'upd ms/it':>10}")
    for r in rows:
        print(f"{r['seeds']:>5} x {r['envs_per_seed']:<4} {r['full_env_steps_per_s']:>13,.0f} "
              f"{r['no_update_env_steps_per_s']:>15,.0f} {r['raw_physics_env_steps_per_s']:>17,.0f}"
              f" {r['full_ms_per_iter']:>10.2f} {r['raw_physics_ms_per_iter']:>10.2f} "
              f"{r['updates_ms_per_iter']:>10.2f}")


if __name__ == "__main__":
    main()
