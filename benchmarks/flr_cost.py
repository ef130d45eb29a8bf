"""What the forward-looking reward of one low-level batch costs, evaluating V on every
transition or only on those that reach their subgoal (``chunk`` rows at a time, for each of
``--chunks``), as the fraction that reaches varies: which ``FLRConfig.value_chunk`` to use.

Eq. (5) evaluates the target actor and both target critics on ``candidates`` next subgoals per
transition; only the reaching transitions' rewards read them. Both ways give the same rewards
(checked here). Random obs and networks at the reference's sizes: the cost does not depend on
the data, only on how many transitions reach.

    python benchmarks/flr_cost.py --out benchmarks/results/flr_cost_cpu.json
    python benchmarks/flr_cost.py --chunks 128,256,512,1024 --fractions 0.65,0.75
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import rewards
from flrjax.agents import gc_td3

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from update_cost import fastest_ms  # noqa: E402

REPEATS = 5  # timed calls after the compiling one; the fastest counts


def time_flr(batch: int, candidates: int, hidden: int, chunks: list[int],
             fractions: list[float], obs_size: int = 30, goal_size: int = 2,
             action_size: int = 8) -> list[dict]:
    """ms per batch, full and with each chunk, at each reaching fraction (rewards checked
    equal)."""
    cfg = gc_td3.TD3Config(hidden_sizes=(hidden,) * 3, batch_size=batch)
    value_fn = functools.partial(
        gc_td3.value, gc_td3.init(jax.random.PRNGKey(0), obs_size, goal_size, action_size, cfg))
    rng = np.random.default_rng(0)
    obs = jnp.asarray(rng.normal(size=(batch, obs_size)), jnp.float32)
    subgoal = jnp.asarray(rng.uniform(-8, 8, (batch, goal_size)), jnp.float32)
    cands = rewards.sample_next_subgoals(jax.random.PRNGKey(1), subgoal, eps=2.0,
                                         num=candidates)
    rows = []
    for frac in fractions:
        reach = rng.random(batch) < frac
        next_achieved = subgoal + jnp.asarray(np.where(reach, 0.1, 1.0)[:, None], jnp.float32)
        out = {}
        for c in (None, *chunks):
            f = jax.jit(lambda *batch, c=c: rewards.forward_looking_reward(
                value_fn, *batch, alpha=0.01, eps=2.0, chunk=c).reward)
            call = functools.partial(f, obs, next_achieved, subgoal, cands)
            out[c] = (fastest_ms(lambda _, call=call: call(), REPEATS), np.asarray(call()))
            if c is not None:  # every chunk size gives the full evaluation's rewards
                np.testing.assert_allclose(out[c][1], out[None][1], rtol=1e-5, atol=1e-6)
        rows.append({"reach_fraction": float(reach.mean()), "full_ms": out[None][0],
                     "chunked_ms": {str(c): out[c][0] for c in chunks}})
    return rows


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument("--candidates", type=int, default=16)
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--chunks", default="128", help="comma-separated chunk sizes")
    p.add_argument("--fractions", default="0.1,0.3,1.0")
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    chunks = [int(x) for x in args.chunks.split(",")]
    rows = time_flr(args.batch, args.candidates, args.hidden, chunks,
                    [float(x) for x in args.fractions.split(",")])
    result = {"benchmark": "flr_cost", "device": str(jax.devices()[0].device_kind),
              "backend": jax.default_backend(), "jax": jax.__version__,
              "batch": args.batch, "candidates": args.candidates, "hidden": args.hidden,
              "chunks": chunks, "rows": rows}
    print(f"FLR of one batch ({args.batch} x {args.candidates} candidates, 3x{args.hidden} "
          f"nets) on {result['device']}, ms; chunk N: N reaching rows at a time")
    print(f"{'reaching':>9} {'full':>8} " + " ".join(f"{f'chunk {c}':>10}" for c in chunks))
    for r in rows:
        print(f"{r['reach_fraction']:>9.2f} {r['full_ms']:>8.1f} "
              + " ".join(f"{r['chunked_ms'][str(c)]:>10.1f}" for c in chunks))
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    return result


if __name__ == "__main__":
    main()
