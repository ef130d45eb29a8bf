"""Env-steps/s of the full training step (act, store, HER sample, TD3 updates) against the same
chunk without updates, the updates alone and raw physics, for seeds x envs-per-seed
configurations. The target is full <= 1.3 x (physics + updates alone) per iteration.

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
from flrjax.agents import gc_td3
from flrjax.algos import flat

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from env_throughput import bench_env  # noqa: E402

REPEATS = 2  # timed calls after the compiling one; the fastest counts


def time_chunk(cfg: train.TrainConfig, keep: bool = False):
    """(compile + first call seconds, fastest of ``REPEATS`` further calls) of one training
    chunk, and the carry after them if ``keep`` (its buffer holds 1 + REPEATS episodes per
    env)."""
    init, chunk, _ = train.build(cfg)
    carry = init(jax.random.split(jax.random.PRNGKey(0), cfg.seeds))
    times = []
    for i in range(1 + REPEATS):
        t0 = time.perf_counter()
        carry, m = chunk(carry, jnp.int32(i))
        jax.block_until_ready(m)
        times.append(time.perf_counter() - t0)
    return (times[0], min(times[1:]), carry) if keep else (times[0], min(times[1:]))


def time_updates(cfg: train.TrainConfig, carry, iters: int) -> tuple[float, float]:
    """(compile + first call, fastest further call) of ``iters`` iterations' updates alone:
    the chunk's update schedule (HER sampling included) on the buffer in ``carry``, no physics."""
    acfg = train.flat_config(cfg)
    group, actor_updates = gc_td3.schedule(acfg.updates_per_iter, acfg.td3.actor_update_freq)
    yes = jnp.bool_(True)

    def one_seed(c, key):
        def one_group(agent, k):
            k_c, k_a = jax.random.split(k)
            agent, _ = jax.lax.scan(
                lambda a, kk: flat.learn(a, c.buffer, kk, yes, acfg.updates_per_iter, 0, acfg),
                agent, jax.random.split(k_c, group))
            return flat.learn(agent, c.buffer, k_a, yes, 0, actor_updates, acfg)[0], None

        return jax.lax.scan(one_group, c.agent, jax.random.split(key, iters // group))[0]

    run = jax.jit(jax.vmap(one_seed))
    keys = jax.random.split(jax.random.PRNGKey(1), cfg.seeds)
    times = []
    for _ in range(1 + REPEATS):
        t0 = time.perf_counter()
        jax.block_until_ready(run(carry, keys))
        times.append(time.perf_counter() - t0)
    return times[0], min(times[1:])


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--configs", default="1x1,5x1,5x16,50x16,5x256", help="SEEDSxENVS,...")
    p.add_argument("--updates-per-step", type=float, default=1.0)
    p.add_argument("--episode-length", type=int, default=600)
    p.add_argument("--algos", default="flat",
                   help="flat, plus dhrl / flr_dhrl to time their full step at the same batch "
                        "(graph rebuilt every episode round, the reference's landmark sizes)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    algos = args.algos.split(",")
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
        c_noupd, t_noupd, filled = time_chunk(no_upd, keep=True)
        c_upd, t_upd = time_updates(base, filled, args.episode_length)
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
            "updates_alone_ms_per_iter": 1e3 * t_upd / iters,
            "compile_s": c_full - t_full,
            "updates_compile_s": c_upd - t_upd,
        }
        row["full_over_physics_plus_updates"] = row["full_ms_per_iter"] / (
            row["raw_physics_ms_per_iter"] + row["updates_alone_ms_per_iter"])
        for algo in (a for a in algos if a != "flat"):
            hier = dataclasses.replace(base, algo=algo, graph_start_steps=0,
                                       graph_every_steps=num_envs * args.episode_length)
            c_h, t_h = time_chunk(hier)
            row[f"{algo}_full_env_steps_per_s"] = seeds * num_envs * iters / t_h
            row[f"{algo}_full_ms_per_iter"] = 1e3 * t_h / iters
            row[f"{algo}_compile_s"] = c_h - t_h
            row[f"{algo}_over_flat"] = t_h / t_full
        rows.append(row)
        print({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
    result = {"benchmark": "train_throughput", "command": "python " + " ".join(sys.argv),
              "device": str(jax.devices()[0].device_kind),
              "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__,
                           "python": platform.python_version()},
              "env": args.env, "algos": algos, "updates_per_step": args.updates_per_step,
              "rows": rows}
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    print(f"\n{args.env}, flat, {args.updates_per_step:g} updates per env step, "
          f"batch 1024, 3x256 MLPs, on {result['device']}")
    print(f"{'seeds x envs':>12} {'full steps/s':>13} {'no-upd steps/s':>15} "
          f"{'raw phys steps/s':>17} {'full ms/it':>10} {'phys ms/it':>10} {'upd ms/it':>10} "
          f"{'full/(phys+upd)':>15}")
    for r in rows:
        print(f"{r['seeds']:>5} x {r['envs_per_seed']:<4} {r['full_env_steps_per_s']:>13,.0f} "
              f"{r['no_update_env_steps_per_s']:>15,.0f} {r['raw_physics_env_steps_per_s']:>17,.0f}"
              f" {r['full_ms_per_iter']:>10.2f} {r['raw_physics_ms_per_iter']:>10.2f} "
              f"{r['updates_alone_ms_per_iter']:>10.2f} "
              f"{r['full_over_physics_plus_updates']:>15.2f}")
    for algo in (a for a in algos if a != "flat"):
        print(f"\n{algo}: full step (graph rebuilt every episode round) vs flat, same batch")
        print(f"{'seeds x envs':>12} {algo + ' steps/s':>18} {algo + ' ms/it':>15} "
              f"{'/ flat':>8}")
        for r in rows:
            print(f"{r['seeds']:>5} x {r['envs_per_seed']:<4} "
                  f"{r[algo + '_full_env_steps_per_s']:>18,.0f} "
                  f"{r[algo + '_full_ms_per_iter']:>15.2f} {r[algo + '_over_flat']:>8.2f}")


if __name__ == "__main__":
    main()
