"""What the forward-looking reward of one low-level batch costs, evaluating V on every
transition or only on those that reach their subgoal (``chunk`` rows at a time), as the
fraction that reaches varies.

Eq. (5) evaluates the target actor and both target critics on ``candidates`` next subgoals per
transition; only the reaching transitions' rewards read them. Both ways give the same rewards
(checked here). Random obs and networks at the reference's sizes: the cost does not depend on
the data, only on how many transitions reach.

    python benchmarks/flr_cost.py --out benchmarks/results/flr_cost_cpu.json
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


def time_flr(batch: int, candidates: int, hidden: int, chunk: int, fractions: list[float],
             obs_size: int = 30, goal_size: int = 2, action_size: int = 8) -> list[dict]:
    """ms per batch, full and chunked, at each reaching fraction (rewards checked equal)."""
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
        for name, c in (("full", None), ("chunked", chunk)):
            f = jax.jit(functools.partial(rewards.forward_looking_reward, value_fn, alpha=0.01,
                                          eps=2.0, chunk=c))
            call = functools.partial(f, obs, next_achieved, subgoal, cands)
            out[name] = (fastest_ms(lambda _, call=call: call(), REPEATS), np.asarray(call()))
        np.testing.assert_allclose(out["chunked"][1], out["full"][1], rtol=1e-5, atol=1e-6)
        rows.append({"reach_fraction": float(reach.mean()), "full_ms": out["full"][0],
                     "chunked_ms": out["chunked"][0]})
    return rows


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", type=int, default=1024)
    p.add_argument("--candidates", type=int, default=16)
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--chunk", type=int, default=128)
    p.add_argument("--fractions", default="0.1,0.3,1.0")
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    rows = time_flr(args.batch, args.candidates, args.hidden, args.chunk,
                    [float(x) for x in args.fractions.split(",")])
    result = {"benchmark": "flr_cost", "device": str(jax.devices()[0].device_kind),
              "backend": jax.default_backend(), "jax": jax.__version__,
              "batch": args.batch, "candidates": args.candidates, "hidden": args.hidden,
              "chunk": args.chunk, "rows": rows}
    print(f"FLR of one batch ({args.batch} x {args.candidates} candidates, 3x{args.hidden} "
          f"nets) on {result['device']}, ms; chunked: {args.chunk} reaching rows at a time")
    print(f"{'reaching':>9} {'full':>8} {'chunked':>8}")
    for r in rows:
        print(f"{r['reach_fraction']:>9.2f} {r['full_ms']:>8.1f} {r['chunked_ms']:>8.1f}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    return result


if __name__ == "__main__":
    main()
