"""The flat learner driven the way the PyTorch references drive theirs, against flrjax's step.

Host loop: one seed at a time, Python calls a jitted ``act``, ``env.step``, replay insert and
TD3 update once per env step (the structure of DHRL's ``collect_experience`` with
``low_agent_optimize`` every step), so every step pays the host round trips. flrjax: the same
work as one jitted ``lax.scan`` chunk, ``vmap``ped over seeds. Paper protocol: one env per
seed, one update per env step, batch 1024, 3x256 MLPs.

    python benchmarks/host_loop_baseline.py --env ant4leg --seeds 5 --out RESULT.json
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

from flrjax import replay, train
from flrjax.agents import gc_td3
from flrjax.algos import flat


def host_loop_steps_per_s(cfg: train.TrainConfig, steps: int) -> tuple[float, float]:
    """(compile seconds, env steps/s) of one seed trained from a Python loop of jitted calls."""
    env, acfg = train.make_env(cfg), train.flat_config(cfg)
    init, chunk, _ = train.build(cfg)
    carry = jax.tree.map(lambda x: x[0], init(jax.random.split(jax.random.PRNGKey(0), 1)))
    carry, _ = jax.jit(lambda c: flat.train_episode(c, jnp.int32(0), env, acfg))(carry)  # fill

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
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    run(steps)
    return compile_s, steps / (time.perf_counter() - t0)


def scanned_steps_per_s(cfg: train.TrainConfig) -> float:
    """Env steps/s (all seeds) of flrjax's jitted chunk, the fastest of two timed calls."""
    init, chunk, _ = train.build(cfg)
    carry = init(jax.random.split(jax.random.PRNGKey(0), cfg.seeds))
    best = float("inf")
    for i in range(3):
        t0 = time.perf_counter()
        carry, m = chunk(carry, jnp.int32(i))
        jax.block_until_ready(m)
        if i:
            best = min(best, time.perf_counter() - t0)
    return cfg.seeds * cfg.steps_per_chunk / best


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--seeds", type=int, default=5, help="seeds of the scanned, vmapped run")
    p.add_argument("--host-steps", type=int, default=300, help="timed steps of the host loop")
    p.add_argument("--episode-length", type=int, default=200)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    cfg = train.TrainConfig(env=args.env, seeds=1, num_envs=1, updates_per_step=1.0,
                            episodes_per_chunk=1, batch_size=1024, hidden=256,
                            buffer_episodes=50, initial_episodes=0,
                            episode_length=args.episode_length, steps=args.episode_length)
    compile_s, host = host_loop_steps_per_s(cfg, args.host_steps)
    scanned = scanned_steps_per_s(dataclasses.replace(cfg, seeds=args.seeds))
    result = {
        "benchmark": "host_loop_baseline", "command": "python " + " ".join(sys.argv),
        "device": str(jax.devices()[0].device_kind),
        "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__,
                     "python": platform.python_version()},
        "env": args.env, "algo": "flat", "protocol": "1 env per seed, 1 update per env step",
        "host_loop_env_steps_per_s_one_seed": host, "host_loop_compile_s": compile_s,
        "scanned_seeds": args.seeds, "scanned_env_steps_per_s_all_seeds": scanned,
        "speedup": scanned / host,
    }
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    print(f"\n{args.env}, flat, paper protocol, on {result['device']}")
    print(f"host loop, 1 seed:          {host:>10,.0f} env steps/s")
    print(f"flrjax scan, {args.seeds} seeds vmapped: {scanned:>10,.0f} env steps/s")
    print(f"speed-up:                   {scanned / host:>10.1f}x")


if __name__ == "__main__":
    main()
