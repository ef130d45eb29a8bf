"""The flat learner driven the way the PyTorch references drive theirs, against flrjax's step.

Host loop: one seed, one env, one update per env step (the reference's protocol), with Python
calling a jitted ``act``, ``env.step``, replay insert and TD3 update once per env step (the
structure of DHRL's ``collect_experience`` with ``low_agent_optimize`` every step), so every
step pays the host round trips. flrjax: the same work as one jitted ``lax.scan`` chunk,
``vmap``ped over seeds, as timed by ``train_throughput.py``; ``--scanned`` names its output,
and the speed-up is given against each of its flat rows (same device, same sizes: batch 1024,
3x256 MLPs).

    python benchmarks/train_throughput.py --env ant4leg --configs 5x1:paper,5x256:fast \\
        --measures flat --out TT.json
    python benchmarks/host_loop_baseline.py --env ant4leg --scanned TT.json --out RESULT.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import mujoco

from flrjax import config, replay, runner
from flrjax.agents import gc_td3
from flrjax.algos import flat

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import train_throughput  # noqa: E402


def host_loop_steps_per_s(cfg: config.TrainConfig, steps: int) -> tuple[float, float]:
    """(seconds of the first 2 steps, compiles included; env steps/s) of one seed trained
    from a Python loop of jitted calls, after one episode of random actions fills the buffer."""
    env = config.make_env(cfg)
    acfg = flat.from_run(cfg, env)
    init, fill, _ = runner.build(dataclasses.replace(cfg, initial_episodes=10**9))
    carry, _ = fill(runner.init_carry(cfg, init, jax.random.PRNGKey(0)), jnp.int32(0))
    carry = jax.tree.map(lambda x: x[0], carry)

    act = jax.jit(lambda agent, s, k: gc_td3.act(agent, s.obs, s.info["goal"], k,
                                                  explore=True))
    step = jax.jit(jax.vmap(env.step))

    @jax.jit
    def store(buffer, s, nxt, action, t):
        buffer = replay.insert_step(buffer, t, {**flat.state_fields(s), "action": action,
                                                "goal": s.info["goal"]})
        return replay.insert_final(buffer, flat.state_fields(nxt))

    @jax.jit
    def update(agent, buffer, k, t):
        agent, _ = flat.learn(agent, buffer, k, jnp.bool_(True), 1, 0, acfg)
        return jax.lax.cond(t % 2 == 1, lambda: flat.learn(agent, buffer, k, jnp.bool_(True),
                                                           0, 1, acfg)[0], lambda: agent)

    def run(n: int) -> None:
        nonlocal carry
        s, buffer, agent, key = carry.env_state, carry.buffer, carry.agent, carry.key
        for t in range(n):
            key, k_act, k_upd = jax.random.split(key, 3)
            action = act(agent, s, k_act)
            nxt = step(s, action)
            buffer = store(buffer, s, nxt, action, t % env.config.episode_length)
            agent = update(agent, buffer, k_upd, t)
            s = nxt
        jax.block_until_ready(agent)
        carry = carry.replace(env_state=s, buffer=buffer, agent=agent, key=key)

    t0 = time.perf_counter()
    run(2)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    run(steps)
    return first, steps / (time.perf_counter() - t0)


def speedups(host: float, scanned: dict) -> list[dict]:
    """flrjax's flat rows from a train_throughput result against the host loop's steps/s."""
    return [{"seeds": r["seeds"], "envs_per_seed": r["envs_per_seed"],
             "protocol": r["protocol"], "updates_per_step": r["updates_per_step"],
             "scanned_env_steps_per_s": r["flat_env_steps_per_s"],
             "speedup": r["flat_env_steps_per_s"] / host}
            for r in scanned["rows"] if "flat_env_steps_per_s" in r]


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--host-steps", type=int, default=500, help="timed steps of the host loop")
    p.add_argument("--episode-length", type=int, default=80)
    p.add_argument("--scanned", default=None, help="a train_throughput.py result (JSON)")
    p.add_argument("--cache", default="runs/jax_cache", help="persistent compilation cache")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    jax.config.update("jax_compilation_cache_dir", args.cache)
    cfg = train_throughput.job_config({"env": args.env, "seeds": 1, "envs": 1,
                                       "protocol": "paper", "measure": "flat",
                                       "episode_length": args.episode_length})
    first, host = host_loop_steps_per_s(cfg, args.host_steps)
    scanned = {}
    if args.scanned:
        with open(args.scanned) as f:
            scanned = json.load(f)
    result = {
        "benchmark": "host_loop_baseline", "command": "python " + " ".join(sys.argv),
        "device": str(jax.devices()[0].device_kind),
        "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__,
                     "python": platform.python_version()},
        "env": args.env, "algo": "flat",
        "host_loop": "1 seed, 1 env, 1 update per env step, batch 1024, 3x256 MLPs",
        "host_loop_env_steps_per_s": host, "host_loop_first_steps_s": first,
        "scanned_from": args.scanned, "rows": speedups(host, scanned) if scanned else [],
    }
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    print(f"\n{args.env}, flat, on {result['device']}")
    print(f"host loop, 1 seed x 1 env, paper protocol: {host:>10,.1f} env steps/s")
    for r in result["rows"]:
        print(f"flrjax scan, {r['seeds']} seeds x {r['envs_per_seed']} envs, {r['protocol']}: "
              f"{r['scanned_env_steps_per_s']:>10,.0f} env steps/s, {r['speedup']:>7.1f}x")


if __name__ == "__main__":
    main()
