"""Probes of DHRL's high level on the point-mass U-maze (quick preset, 2 seeds, CPU).

    python probe.py dhrl [--steps N] [--low k=v ...] [--high k=v ...]  # every 4k steps
    python probe.py flat [--steps N]  # flat TD3+HER: eval and replay coverage
    python probe.py map [--steps N]   # train DHRL, then roll the hierarchy out per goal region

``--low`` / ``--high`` override fields of the low / high ``TD3Config`` (e.g. ``random_eps=0``).
Columns of ``dhrl``: eval success and final goal distance; the high actor's subgoal ``pi``
from the start towards (0, 16), its normalised output ``u``, Q(pi) and the grid argmax of
Q(start, (0, 16), .); on a high HER batch (relabelled goals): the fraction of saturated actor
outputs (any |u| > 0.99; ``sat|far`` for goals > 10 from the state), Q of the actor's subgoal
and of the hindsight subgoal ag2; ``r0|off>=2``: the fraction of zero rewards beyond the
trivial offset 1, for ag2 within 0.5 of a wall or in the open; replay coverage: stored
high-level states within 3 of (0, 16) and within 4 of the bend (16, 8); ``edge``: fraction of
the last 40 episodes' subgoals at the box edge (|u| > 0.97); ``hq``: the high critic's mean Q.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import planner, replay, rewards, runner
from flrjax.agents import gc_td3
from flrjax.algos import dhrl, hierarchy
from flrjax.config import TrainConfig, algo_config, make_env

G = jnp.array([0.0, 16.0])
BEND = jnp.array([16.0, 8.0])
S0 = jnp.zeros(4)


def config(algo: str, steps: int) -> TrainConfig:
    """The quick preset's sizes, as ``--preset quick --seeds 2`` gives them."""
    return TrainConfig(env="point4leg", algo=algo, seeds=2, num_envs=4, steps=steps,
                       updates_per_step=1.0, episodes_per_chunk=10, batch_size=256,
                       hidden=64, buffer_episodes=400, initial_episodes=8, polyak=0.99,
                       target_update_freq=1)


def patch_dhrl(low: dict, high: dict) -> None:
    """Make ``dhrl.from_run`` override TD3Config fields of either level."""
    orig = dhrl.from_run

    def patched(cfg, env):
        d = orig(cfg, env)
        return dataclasses.replace(d, low=dataclasses.replace(d.low, **low),
                                   high=dataclasses.replace(d.high, **high))

    dhrl.from_run = patched


def at_wall(env, xy: jax.Array) -> jax.Array:
    """True where a 0.5 step in some axis direction leaves the free space."""
    steps = jnp.array([[0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5]])
    return ~jnp.stack([env.maze.is_free(xy + d) for d in steps]).all(0)


def probe_high(c: dhrl.Carry, key: jax.Array, env, acfg: dhrl.DHRLConfig) -> str:
    high = c.high
    sc, off = np.array(acfg.high.action_max), np.array(acfg.high.action_offset)
    gx, gy = np.meshgrid(np.linspace(-4, 20, 25), np.linspace(-4, 20, 25), indexing="ij")
    grid = jnp.asarray(np.stack([gx.ravel(), gy.ravel()], -1), jnp.float32)
    pi = gc_td3.policy(high, high.actor.params, S0[None], G[None])[0]
    u = (np.asarray(pi) - off) / sc
    q = gc_td3.q_value(high, jnp.broadcast_to(S0, (len(grid), 4)),
                       jnp.broadcast_to(G, (len(grid), 2)), grid)
    q_pi = gc_td3.q_value(high, S0[None], G[None], pi[None])[0]
    b = replay.sample(c.high_buffer, key, 1024, future_p=1.0, future_step=acfg.high.future_step)
    p = gc_td3.policy(high, high.actor.params, b["obs"], b["goal"])
    sat = jnp.any(jnp.abs((p - off) / sc) > 0.99, -1)
    far = jnp.linalg.norm(b["goal"] - b["obs"][:, :2], axis=-1) > 10
    q_pi_b = gc_td3.q_value(high, b["obs"], b["goal"], p).mean()
    q_ag2_b = gc_td3.q_value(high, b["obs"], b["goal"], b["next_achieved_goal"]).mean()
    r = rewards.sparse_reward(b["next_achieved_goal"], b["goal"], delta=acfg.delta)
    wall, beyond = at_wall(env, b["next_achieved_goal"]), b["offset"] >= 2

    def frac(x, m):
        return float(jnp.sum(x & m) / jnp.maximum(jnp.sum(m), 1))

    n = replay.num_sampleable(c.high_buffer)
    ag = c.high_buffer.states["achieved_goal"]
    valid = jnp.broadcast_to((jnp.arange(ag.shape[0]) < n)[:, None], ag.shape[:2])
    a = c.high_buffer.transitions["action"]
    edge = jnp.any(jnp.abs((a - off) / sc) > 0.97, -1)
    recent = ((c.high_buffer.ptr - 1 - jnp.arange(a.shape[0])) % a.shape[0]) < 40
    recent = jnp.broadcast_to(recent[:, None], edge.shape)
    return (f"pi={np.asarray(pi).round(2)} u={u.round(3)} Q(pi)={float(q_pi):.2f} "
            f"maxQgrid={float(q.max()):.2f}@{np.asarray(grid[int(jnp.argmax(q))])} | batch: "
            f"sat={float(sat.mean()):.2f} sat|far={frac(sat, far):.2f} Qpi={float(q_pi_b):.2f} "
            f"Qag2={float(q_ag2_b):.2f} r0|off>=2: wall={frac(r == 0, beyond & wall):.3f} "
            f"open={frac(r == 0, beyond & ~wall):.3f} | buf: "
            f"ag~G={frac(jnp.linalg.norm(ag - G, axis=-1) < 3, valid):.3f} "
            f"ag~bend={frac(jnp.linalg.norm(ag - BEND, axis=-1) < 4, valid):.3f} "
            f"edge={frac(edge, recent):.2f}")


def run(cfg: TrainConfig, every_chunk=None):
    init, chunk, evaluate = runner.build(cfg)
    key = jax.random.PRNGKey(cfg.seed)
    carry = runner.init_carry(cfg, init, key)
    t0 = time.time()
    for i in range(cfg.steps // cfg.steps_per_chunk):
        carry, m = chunk(carry, jnp.int32(i * cfg.episodes_per_chunk))
        if every_chunk is not None:
            ev = evaluate(carry, runner.run_keys(cfg, jax.random.fold_in(key, 100 + i)))
            for s in range(cfg.seeds):
                c = jax.tree.map(functools.partial(lambda x, s: x[s], s=s), carry)
                print(f"step {(i + 1) * cfg.steps_per_chunk} seed {s}: "
                      f"succ={float(ev['success_rate'][s]):.2f} "
                      f"gd={float(ev['final_goal_distance'][s]):.1f} "
                      f"{every_chunk(c, m, s, i)} ({time.time() - t0:.0f}s)", flush=True)
    jax.block_until_ready(carry)
    return carry, time.time() - t0


def rollout(c: dhrl.Carry, goal: jax.Array, env, acfg: dhrl.DHRLConfig, n: int = 5):
    """The deterministic hierarchy with the planner (as dhrl.evaluate) towards ``goal``:
    final goal distances [n] and, for episode 0, the state, subgoal and path length per
    period."""
    key = jax.random.key(3)
    s = jax.vmap(lambda k: env.reset_with_goal(k, goal))(jax.random.split(key, n))
    advance = jax.vmap(functools.partial(planner.advance, reach_eps=acfg.reach_eps))

    def period(s, _):
        sg = gc_td3.act(c.high, s.obs, s.info["goal"], key, explore=False)
        path = hierarchy.find_paths(c.low, c.graph, s.obs, sg, acfg)
        fol = jax.vmap(lambda _: planner.follower_init())(jnp.arange(n))

        def step(carry, _):
            s, fol = carry
            fol, wp = advance(fol, path, s.info["achieved_goal"], sg)
            a = gc_td3.act(c.low, s.obs, wp, key, explore=False)
            return (jax.vmap(env.step)(s, a), fol), None

        (s2, _), _ = jax.lax.scan(step, (s, fol), None, length=acfg.subgoal_freq)
        return s2, (s.info["achieved_goal"][0], sg[0], path.length[0])

    periods = env.config.episode_length // acfg.subgoal_freq
    s, (xy, sg, pl) = jax.lax.scan(period, s, None, length=periods)
    return s.info["goal_distance"], xy, sg, pl


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=("dhrl", "flat", "map"))
    p.add_argument("--steps", type=int, default=24_000)
    p.add_argument("--low", nargs="*", default=[])
    p.add_argument("--high", nargs="*", default=[])
    args = p.parse_args()
    low = {k: float(v) for k, v in (x.split("=") for x in args.low)}
    high = {k: float(v) for k, v in (x.split("=") for x in args.high)}
    patch_dhrl(low, high)
    print(f"mode {args.mode}, steps {args.steps}, low overrides {low}, high overrides {high}")
    if args.mode == "flat":
        def cover(c, m, s, i):
            n = int(replay.num_sampleable(c.buffer))
            ag = c.buffer.states["achieved_goal"][:n]
            near = float(jnp.mean(jnp.linalg.norm(ag - G, axis=-1) < 3))
            bend = float(jnp.mean(jnp.linalg.norm(ag - BEND, axis=-1) < 4))
            return f"buf: ag~G={near:.3f} ag~bend={bend:.3f}"

        run(config("flat", args.steps), cover)
        return
    cfg = config("dhrl", args.steps)
    env, acfg = make_env(cfg), algo_config(cfg)
    if args.mode == "dhrl":
        run(cfg, lambda c, m, s, i: probe_high(c, jax.random.key(i), env, acfg)
            + f" hq={float(np.asarray(m['high_q'])[s].mean()):.2f}")
        return
    carry, dt = run(cfg)
    print(f"trained {args.steps} steps in {dt:.0f}s")
    goals = jnp.array([[8.0, 0.0], [16.0, 0.0], [16.0, 8.0], [16.0, 16.0], [8.0, 16.0],
                       [0.0, 16.0]])
    for s in range(cfg.seeds):
        c = jax.tree.map(functools.partial(lambda x, s: x[s], s=s), carry)
        lm = np.asarray(c.graph.landmarks.goal)[np.asarray(c.graph.landmarks.mask)]
        print(f"--- seed {s}: {len(lm)} landmarks, {int((lm[:, 1] > 8).sum())} with y > 8")
        for g in goals:
            d, xy, sg, pl = rollout(c, g, env, acfg)
            xy, sg = (np.asarray(x, np.float64).round(1).tolist() for x in (xy, sg))
            trace = " ".join(f"{a}->{b}({int(n)})" for a, b, n in zip(xy, sg, pl, strict=True))
            print(f"  goal {np.asarray(g)}: final dist {np.asarray(d).round(1)} | episode 0, "
                  f"per period: xy->subgoal(path length) {trace}")


if __name__ == "__main__":
    main()
