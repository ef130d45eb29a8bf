"""Where the update time of one DHRL subgoal period goes: the low level's updates, the high
level's updates, and the high level's updates without subgoal testing.

Subgoal testing (the reference's ``dist_from_graph_to_goal``) evaluates the low level's
distance critics, and its actor, on every landmark x tested-subgoal pair of each high-level
critic batch: 300 x 205 pairs per update in the paper's setting. The "without" row replaces
it by the hindsight rewards alone, to show what it costs; training always does it.

    python benchmarks/update_cost.py --env ant4leg --out benchmarks/results/update_cost_cpu.json

Buffers and graph are filled with zeros at full size: the cost does not depend on the data.
"""

from __future__ import annotations

import argparse
import functools
import json
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from flrjax import config, replay
from flrjax.agents import gc_td3
from flrjax.algos import dhrl, hierarchy, low_batches

REPEATS = 3  # timed calls after the compiling one; the fastest counts


def _full(buffer: replay.ReplayState) -> replay.ReplayState:
    return buffer.replace(count=jnp.full_like(buffer.count, buffer.states["obs"].shape[0]))


def period_updates(cfg: config.TrainConfig) -> dict:
    """Jitted ``(low, high, key) -> (low, high)`` functions of one subgoal period's updates,
    by part, for ``cfg``'s DHRL (or FLR+DHRL) config, and the counts they run."""
    env = config.make_env(cfg)
    acfg = hierarchy.from_run(cfg, env, dhrl.DHRLConfig)
    carry = dhrl.init(jax.random.PRNGKey(0), env, acfg)
    low_buf, high_buf = _full(carry.low_buffer), _full(carry.high_buffer)
    lm = carry.graph.landmarks
    graph = carry.graph.replace(landmarks=lm.replace(mask=jnp.ones_like(lm.mask)))
    sample, sample_g, sample_actor = low_batches.low_samplers(low_buf, acfg)
    k = acfg.subgoal_freq
    low_critic = k * acfg.updates_per_iter
    low_actor = low_critic // acfg.low.actor_update_freq
    high_critic = acfg.high_updates_per_period
    high_actor = high_critic // acfg.high.actor_update_freq

    def hindsight(_: gc_td3.AgentState, key: jax.Array) -> dict:
        """The high batch's draw and hindsight subgoals, without subgoal testing."""
        b = replay.sample(high_buf, key, acfg.high.batch_size, future_p=1.0,
                          future_step=acfg.high.future_step)
        return {**b, "action": b["next_achieved_goal"],
                "reward": jnp.full((acfg.high.batch_size,), -1.0)}

    def low_updates(low, high, key):
        k_c, k_a = jax.random.split(key)
        low, _ = gc_td3.learn(low, sample, k_c, critic_updates=low_critic, actor_updates=0,
                              sample_g=sample_g)
        return gc_td3.learn(low, sample_actor, k_a, critic_updates=0,
                            actor_updates=low_actor)[0], high

    def high_updates(low, high, key, testing: bool):
        s = (functools.partial(dhrl.high_batch, high_buf, hierarchy.dist_fn(low), graph, cfg=acfg)
             if testing else hindsight)
        return low, gc_td3.learn(high, s, key, critic_updates=high_critic,
                                 actor_updates=high_actor)[0]

    parts = {"low": low_updates,
             "high": functools.partial(high_updates, testing=True),
             "high_without_testing": functools.partial(high_updates, testing=False)}
    counts = {"env_steps": k, "low_critic": low_critic, "low_actor": low_actor,
              "high_critic": high_critic, "high_actor": high_actor,
              "landmarks": int(lm.mask.shape[0]),
              "tested_subgoals": round(acfg.subgoal_test_p * acfg.high.batch_size)}
    return {"parts": {n: jax.jit(f) for n, f in parts.items()}, "carry": carry,
            "counts": counts}


def fastest_ms(call: Callable[[int], Any], repeats: int) -> float:
    """ms of the fastest of ``call(1)`` ... ``call(repeats)``, after a first (compiling)
    ``call(0)``; ``i`` may pick each call's inputs."""
    jax.block_until_ready(call(0))
    times = []
    for i in range(1, repeats + 1):
        t0 = time.perf_counter()
        jax.block_until_ready(call(i))
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def time_parts(cfg: config.TrainConfig) -> dict:
    """ms per subgoal period of each part (fastest of ``REPEATS`` calls after compiling)."""
    built = period_updates(cfg)
    low, high = built["carry"].low, built["carry"].high
    out = {name: fastest_ms(lambda i, f=f: f(low, high, jax.random.PRNGKey(i)), REPEATS)
           for name, f in built["parts"].items()}
    return {"ms_per_period": out, "counts": built["counts"]}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--algo", default="dhrl", choices=("dhrl", "flr_dhrl"))
    p.add_argument("--updates-per-step", type=float, default=1.0,
                   help="low-level updates per env step (1: the paper's protocol, 1 env)")
    p.add_argument("--batch-size", type=int, default=1024)
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--max-landmarks", type=int, default=None)
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    cfg = config.make(dict(env=args.env, algo=args.algo, num_envs=1,
                           updates_per_step=args.updates_per_step, batch_size=args.batch_size,
                           hidden=args.hidden, max_landmarks=args.max_landmarks))
    result = {"benchmark": "update_cost", "device": jax.devices()[0].device_kind,
              "backend": jax.default_backend(), "jax": jax.__version__, "env": args.env,
              "algo": args.algo, "updates_per_step": args.updates_per_step,
              "batch_size": args.batch_size, "hidden": args.hidden, **time_parts(cfg)}
    ms, n = result["ms_per_period"], result["counts"]
    print(f"{args.env} {args.algo}, {result['device']}, one subgoal period ({n['env_steps']} "
          f"env steps), batch {args.batch_size}, {n['landmarks']} landmarks x "
          f"{n['tested_subgoals']} tested subgoals")
    print(f"{'part':<22}{'updates':>16}{'ms':>10}")
    rows = (("low", f"{n['low_critic']} + {n['low_actor']} actor"),
            ("high", f"{n['high_critic']} + {n['high_actor']} actor"),
            ("high_without_testing", f"{n['high_critic']} + {n['high_actor']} actor"))
    for name, updates in rows:
        print(f"{name:<22}{updates:>16}{ms[name]:>10.1f}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
