"""Memory of the landmark distance matrices: the low level's distance critics on all K x K
landmark pairs (the graph rebuild) and on the K x 205 pairs of landmarks and tested subgoals
(every high-level update's subgoal testing), vmapped over seeds, evaluated in one call against
``planner.PAIRWISE_ROWS`` rows per call. XLA's memory analysis of the compiled function alone
(nothing is allocated), so it runs on the CPU in seconds.

    python benchmarks/pairwise_memory.py --env ant4leg --seeds 100 \\
        --out benchmarks/results/pairwise_memory.json
"""

from __future__ import annotations

import argparse
import functools
import json

import jax
import jax.numpy as jnp

from flrjax import config, planner
from flrjax.agents import gc_td3
from flrjax.algos import dhrl


def temp_gib(env_name: str, seeds: int, rows: int, goals: int | None = None) -> float:
    """GiB of temporaries XLA's compiled ``pairwise_distance`` needs for ``seeds`` seeds of
    the default DHRL config on ``env_name`` (3x256 critics, 300 landmarks), from every landmark
    to ``goals`` goals (default: the landmarks)."""
    cfg = config.TrainConfig(env=env_name, algo="dhrl", seeds=seeds)
    env = config.make_env(cfg)
    acfg = dhrl.from_run(cfg, env)
    k, obs = acfg.max_nodes, env.observation_size
    goals = k if goals is None else goals
    low = jax.eval_shape(jax.vmap(lambda key: gc_td3.init(key, obs, 2, env.action_size,
                                                          acfg.low)),
                         jax.random.split(jax.random.PRNGKey(0), seeds))
    run = jax.jit(jax.vmap(lambda a, o, g: planner.pairwise_distance(
        functools.partial(gc_td3.distance, a), o, g, rows=rows)))
    lowered = run.lower(low, jax.ShapeDtypeStruct((seeds, k, obs), jnp.float32),
                        jax.ShapeDtypeStruct((seeds, goals, 2), jnp.float32))
    mem = lowered.compile().memory_analysis()
    return mem.temp_size_in_bytes / 2**30


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--seeds", type=int, default=100)
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    acfg = config.algo_config(config.TrainConfig(env=args.env, algo="dhrl"))
    k, n_test = acfg.max_nodes, round(acfg.subgoal_test_p * acfg.high.batch_size)
    result = {"benchmark": "pairwise_memory", "env": args.env, "seeds": args.seeds,
              "landmarks": k, "tested_subgoals": n_test, "backend": jax.default_backend(),
              "jax": jax.__version__, "rows_per_call": planner.PAIRWISE_ROWS, "temp_gib": {}}
    for name, goals in (("graph", None), ("subgoal_testing", n_test)):
        for calls, rows in (("one_call", k), ("row_blocks", planner.PAIRWISE_ROWS)):
            gib = temp_gib(args.env, args.seeds, rows, goals)
            result["temp_gib"][f"{name}_{calls}"] = gib
            print(f"{args.env}, {args.seeds} seeds, {name}: {k} x {goals or k} pairs, "
                  f"{calls}: {gib:.2f} GiB of temporaries")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
