"""One low-level update of DHRL / FLR+DHRL, vmapped over seeds: milliseconds, FLOPs and the
achieved TFLOP/s.

"One update" is what the trainer does per gradient step of one seed's low level: a HER batch
for the main critics with its reward (eq. 1, or eq. 5's candidate values for the transitions
that reach their subgoal), a second batch for the distance critics, both twin-critic Adam
steps, the masked target update, and half an actor step (the actor steps once per two critic
steps). Timed as ``--updates`` such updates in one jitted scan, fastest of ``--repeats`` calls.

The replay holds random data; a fraction ``--reach-frac`` of each main batch is made to reach
its subgoal (0.63-0.73 in the tripod figure runs' logs, column ``reach_frac``), since eq. 5's
cost follows it.

FLOPs are counted from the layer sizes, 2 per multiply-add, matrix products only:
- forward of an MLP on one sample: ``f = 2 * sum(fan_in * fan_out)``;
- a critic step (twin): forward, input and weight gradients of both critics on the batch
  (``3 f_c`` each), and the target: target actor and both target critics (``f_a + 2 f_c``);
- eq. 5: ``reach_frac * B * M`` candidate values, each a target actor and two target critics
  (``f_a + 2 f_c``);
- an actor step: actor forward and both gradients (``3 f_a``), the first critic forward and its
  input gradient (``2 f_c``); half of it per update.

The FLOPs are the same with ``-train16`` (bf16 updates): the same products, faster units.

    python benchmarks/low_update.py --variants dhrl,f32,bf16 --out RESULT.json
    python benchmarks/low_update.py --variants dhrl,dhrl-train16,bf16-c0,bf16-c0-train16
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys

import jax
import jax.numpy as jnp

from flrjax import config, metrics_io, replay, runner
from flrjax.agents import gc_td3
from flrjax.agents.gc_td3 import fused_value
from flrjax.algos import dhrl, hierarchy
from flrjax.algos import flr as flr_config

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import step_profile  # noqa: E402
from update_cost import fastest_ms  # noqa: E402

#: Dense peak TFLOP/s of the matrix units by the vendor's datasheet (H100 SXM), for the ratio.
PEAK_TFLOPS = {"tf32": 495.0, "bf16": 989.0}


def mlp_flops(sizes: tuple[int, ...]) -> int:
    """FLOPs of one forward pass of an MLP with layer sizes ``sizes`` (in, hidden..., out)."""
    return 2 * sum(a * b for a, b in zip(sizes[:-1], sizes[1:], strict=False))


def update_flops(obs: int, goal: int, action: int, hidden: tuple[int, ...], batch: int,
                 reach: float, candidates: int, flr: bool) -> dict[str, float]:
    """FLOPs per seed of one low-level update, by part (see the module docstring)."""
    f_a = mlp_flops((obs + goal, *hidden, action))
    f_c = mlp_flops((obs + goal + action, *hidden, 1))
    critic_step = batch * (2 * 3 * f_c + f_a + 2 * f_c)
    parts = {"critic_main": critic_step, "critic_g": critic_step,
             "flr_values": reach * batch * candidates * (f_a + 2 * f_c) if flr else 0.0,
             "actor_half": 0.5 * batch * (3 * f_a + 2 * f_c)}
    parts["total"] = sum(parts.values())
    return parts


def variant_config(base: config.TrainConfig, name: str) -> config.TrainConfig:
    """``name``: ``dhrl``, or FLR settings joined by ``-``: ``f32``/``bf16`` (precision of the
    candidate values), ``mN`` (N candidates), ``cN`` (value chunk N; ``c0``: all at once),
    ``xla``/``fused`` (how the candidate values are computed); either followed by ``-train16``
    for bf16 updates (``--train-precision bfloat16``; float32 without it, whatever the
    trainer's default on the device)."""
    parts = name.split("-")
    train16 = parts[-1] == "train16"
    base = dataclasses.replace(base, train_precision="bfloat16" if train16 else "float32")
    parts = parts[:-1] if train16 else parts
    if parts == ["dhrl"]:
        return dataclasses.replace(base, algo="dhrl")
    cfg = dataclasses.replace(base, algo="flr_dhrl")
    for part in parts:
        if part in ("f32", "bf16"):
            cfg = dataclasses.replace(
                cfg, flr_precision="bfloat16" if part == "bf16" else "float32")
        elif part[0] == "m":
            cfg = dataclasses.replace(cfg, flr_candidates=int(part[1:]))
        elif part[0] == "c":
            cfg = dataclasses.replace(cfg, flr_value_chunk=int(part[1:]))
        elif part in fused_value.KERNELS:
            cfg = dataclasses.replace(cfg, value_kernel=part)
        else:
            raise SystemExit(f"unknown variant part {part!r} in {name!r}")
    config.validate(cfg)
    return cfg


def random_buffer(buffer: replay.ReplayState, key: jax.Array) -> replay.ReplayState:
    """The buffer full, its float fields random normal (never time on zeros)."""
    leaves, tree = jax.tree.flatten(buffer.states)
    keys = jax.random.split(key, len(leaves))
    states = jax.tree.unflatten(tree, [
        jax.random.normal(k, x.shape, x.dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x
        for k, x in zip(keys, leaves, strict=True)])
    return buffer.replace(states=states,
                          count=jnp.full_like(buffer.count, buffer.states["obs"].shape[0]))


def low_updates(cfg: config.TrainConfig, updates: int, reach_frac: float,
                options: dict | None = None):
    """(jitted ``f(agents[S], key) -> agents[S]`` running ``updates`` low-level updates per
    seed, the seeds' agents, the sizes for the FLOP count), compiled with XLA's ``options``."""
    env = config.make_env(cfg)
    acfg = dhrl.from_run(cfg, env)  # with the FLR of an flr_* algo
    carry = dhrl.init(jax.random.PRNGKey(0), env, acfg)
    buffer = random_buffer(carry.low_buffer, jax.random.PRNGKey(1))
    _, sample_g, sample_actor = hierarchy.low_samplers(buffer, acfg)
    b = acfg.low.batch_size
    far = jnp.arange(b) >= round(reach_frac * b)

    def sample(agent: gc_td3.AgentState, key: jax.Array) -> dict:
        batch = sample_actor(agent, key)
        batch["next_achieved_goal"] = jnp.where(far[:, None], batch["goal"] + 10.0,
                                                batch["goal"])
        batch["reward"], batch["metrics"] = hierarchy.low_reward(
            agent, batch, jax.random.split(key)[1], acfg)
        return batch

    def one_seed(agent: gc_td3.AgentState, key: jax.Array) -> gc_td3.AgentState:
        k_c, k_a = jax.random.split(key)
        agent, _ = gc_td3.learn(agent, sample, k_c, critic_updates=updates, actor_updates=0,
                                sample_g=sample_g)
        return gc_td3.learn(agent, sample_actor, k_a, critic_updates=0,
                            actor_updates=updates // 2)[0]

    agents = jax.vmap(lambda k: gc_td3.init(k, env.observation_size, 2, env.action_size,
                                            acfg.low))(jax.random.split(jax.random.PRNGKey(2),
                                                                        cfg.seeds))
    sizes = dict(obs=env.observation_size, goal=2, action=env.action_size,
                 hidden=acfg.low.hidden_sizes, batch=b)
    return jax.jit(jax.vmap(one_seed), compiler_options=options), agents, sizes


def time_variant(cfg: config.TrainConfig, updates: int, reach_frac: float, repeats: int,
                 options: dict | None = None) -> dict:
    """ms per update (all seeds), FLOPs per update (all seeds) and TFLOP/s of one variant."""
    f, agents, sizes = low_updates(cfg, updates, reach_frac, options)
    keys = [jax.random.split(jax.random.PRNGKey(10 + i), cfg.seeds) for i in range(repeats + 1)]
    ms = fastest_ms(lambda i: f(agents, keys[i]), repeats) / updates
    flr = flr_config.from_run(cfg)
    flops = update_flops(**sizes, reach=reach_frac,
                         candidates=flr.num_candidates if flr else 0, flr=flr is not None)
    flops = {k: v * cfg.seeds for k, v in flops.items()}
    return {"ms_per_update": ms, "gflop_per_update": {k: v / 1e9 for k, v in flops.items()},
            "tflops": flops["total"] / ms / 1e9}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant3leg")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--batch-size", type=int, default=1024)
    p.add_argument("--hidden", type=int, default=256)
    p.add_argument("--updates", type=int, default=40, help="updates per timed call")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--reach-frac", type=float, default=0.7)
    p.add_argument("--variants", default="dhrl,f32,bf16",
                   help="comma-separated: dhrl, or f32|bf16 with -mN (candidates) and -cN "
                        "(value chunk), e.g. bf16-m8-c0; -train16 at the end: bf16 updates")
    p.add_argument("--compile-options", default="default",
                   help="step_profile.py's XLA option presets joined by '+', e.g. serial")
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    # the trainer's XLA options, the presets over them
    options = {**runner.COMPILER_OPTIONS, **step_profile.compile_options(args.compile_options)}
    base = config.TrainConfig(env=args.env, algo="dhrl", seeds=args.seeds, num_envs=1,
                              updates_per_step=1.0, batch_size=args.batch_size,
                              hidden=args.hidden, buffer_episodes=20, steps=3000, devices=1)
    result = {"benchmark": "low_update", **metrics_io.provenance(),
              "device": jax.devices()[0].device_kind,
              "backend": jax.default_backend(), "jax": jax.__version__, "env": args.env,
              "seeds": args.seeds, "batch_size": args.batch_size, "hidden": args.hidden,
              "reach_frac": args.reach_frac, "updates_per_call": args.updates,
              "compiler_options": options,
              "peak_tflops_datasheet": PEAK_TFLOPS, "variants": {}}
    for name in args.variants.split(","):
        r = time_variant(variant_config(base, name), args.updates, args.reach_frac,
                         args.repeats, options)
        result["variants"][name] = r
        print(f"{name:<16}{r['ms_per_update']:8.3f} ms  {r['gflop_per_update']['total']:7.1f} "
              f"GFLOP  {r['tflops']:6.1f} TFLOP/s", flush=True)
    if args.out:
        metrics_io.write_json(args.out, result)


if __name__ == "__main__":
    main()
