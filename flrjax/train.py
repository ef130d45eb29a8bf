"""``python -m flrjax.train``: the scanned, seed-vmapped trainer.

A run is a host loop over *chunks*. A chunk is one jitted call: ``vmap`` over seeds of a
``lax.scan`` over ``episodes_per_chunk`` lockstep episodes, each a ``lax.scan`` over the
episode's env steps (act, store, update). Between chunks the host evaluates, writes
``metrics.csv``, shows progress and checkpoints; nothing inside a chunk touches the host.

    python -m flrjax.train --env point3leg --seeds 2 --preset quick
    python -m flrjax.train --env ant4leg --seeds 5 --num-envs 16 --updates-per-step 0.0625
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import functools
import json
import os
import sys
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import envs
from flrjax.agents import gc_td3
from flrjax.algos import flat

ALGOS = ("flat",)
METRIC_FIELDS = ("step", "seed", "success_rate", "final_goal_distance", "falls",
                 "final_torso_z", "random_goal_success", "random_goal_distance", "critic_loss",
                 "q", "train_success", "wall_time", "env_steps_per_s")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a run. ``steps`` counts env steps per seed (all envs)."""

    env: str = "point3leg"
    algo: str = "flat"
    seeds: int = 1
    seed: int = 0
    steps: int = 20_000
    num_envs: int = 1
    # Gradient updates per env step; the paper protocol (the reference) is 1 with 1 env.
    updates_per_step: float = 1.0
    episodes_per_chunk: int = 5
    eval_episodes: int = 10
    batch_size: int = 1024
    hidden: int = 256
    buffer_episodes: int = 2500  # replay capacity per seed (1.5M transitions at T = 600)
    initial_episodes: int = 10
    episode_length: int | None = None  # env override; None = the env's own
    out: str | None = None

    @property
    def horizon(self) -> int:
        return self.episode_length or envs.make(self.env).config.episode_length

    @property
    def steps_per_chunk(self) -> int:
        return self.num_envs * self.horizon * self.episodes_per_chunk

    @property
    def updates_per_iter(self) -> int:
        return round(self.num_envs * self.updates_per_step)


PRESETS: dict[str, dict] = {
    # Finishes in a minute or two on a laptop CPU: small networks and batches, point mass.
    "quick": dict(steps=24_000, num_envs=4, updates_per_step=1.0, episodes_per_chunk=10,
                  batch_size=256, hidden=64, buffer_episodes=400, initial_episodes=8),
    # The reference's scale: 3x256 networks, batch 1024, one update per env step.
    "paper": dict(steps=1_200_000, num_envs=1, updates_per_step=1.0, episodes_per_chunk=5,
                  batch_size=1024, hidden=256, buffer_episodes=2500, initial_episodes=10),
}


class ConfigError(ValueError):
    """A bad flag or combination of flags; shown as one line, without a traceback."""


def validate(cfg: TrainConfig) -> None:
    """Raise :class:`ConfigError` naming the first bad field."""
    if cfg.env not in envs.names():
        raise ConfigError(f"unknown env {cfg.env!r}; valid: {', '.join(envs.names())}")
    if cfg.algo not in ALGOS:
        raise ConfigError(f"unknown algo {cfg.algo!r}; valid: {', '.join(ALGOS)}")
    for name in ("seeds", "steps", "num_envs", "episodes_per_chunk", "eval_episodes",
                 "batch_size", "hidden", "buffer_episodes"):
        if getattr(cfg, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be >= 1, got "
                              f"{getattr(cfg, name)}")
    if cfg.initial_episodes < 0:
        raise ConfigError(f"--initial-episodes must be >= 0, got {cfg.initial_episodes}")
    if cfg.episode_length is not None and cfg.episode_length < 2:
        raise ConfigError(f"--episode-length must be >= 2, got {cfg.episode_length}")
    iters = cfg.num_envs * cfg.updates_per_step
    if cfg.updates_per_step <= 0 or abs(iters - round(iters)) > 1e-9:
        raise ConfigError(f"--updates-per-step x --num-envs must be a positive integer "
                          f"(updates per vectorised step), got {iters:g}")
    if cfg.steps % cfg.steps_per_chunk:
        raise ConfigError(f"--steps ({cfg.steps}) must be a multiple of num_envs x episode "
                          f"length x episodes_per_chunk = {cfg.steps_per_chunk}")
    if cfg.buffer_episodes < cfg.num_envs:
        raise ConfigError(f"--buffer-episodes ({cfg.buffer_episodes}) must be >= --num-envs "
                          f"({cfg.num_envs})")


def make_env(cfg: TrainConfig):
    extra = {} if cfg.episode_length is None else {"episode_length": cfg.episode_length}
    return envs.make(cfg.env, **extra)


def flat_config(cfg: TrainConfig) -> flat.FlatConfig:
    td3 = gc_td3.TD3Config(hidden_sizes=(cfg.hidden,) * 3, batch_size=cfg.batch_size)
    return flat.FlatConfig(num_envs=cfg.num_envs, updates_per_iter=cfg.updates_per_iter,
                           buffer_episodes=cfg.buffer_episodes,
                           initial_episodes=cfg.initial_episodes,
                           eval_episodes=cfg.eval_episodes, delta=make_env(cfg).config.delta,
                           td3=td3)


def build(cfg: TrainConfig) -> tuple[Callable, Callable, Callable]:
    """(init(keys[S]), chunk(carry[S], first_episode), evaluate(carry[S], keys[S])), jitted.

    Cached on the fields that shape the computation, so runs that differ only in seed, length
    or output directory reuse the compiled chunk.
    """
    return _build(dataclasses.replace(cfg, out=None, seed=0, steps=cfg.steps_per_chunk))


@functools.cache
def _build(cfg: TrainConfig) -> tuple[Callable, Callable, Callable]:
    env, acfg = make_env(cfg), flat_config(cfg)

    def chunk(carry, first_episode):
        episodes = first_episode + jnp.arange(cfg.episodes_per_chunk)

        def one_seed(c):
            return jax.lax.scan(lambda c, e: flat.train_episode(c, e, env, acfg), c, episodes)

        return jax.vmap(one_seed)(carry)

    init = jax.jit(jax.vmap(lambda k: flat.init(k, env, acfg)))
    evaluate = jax.jit(jax.vmap(lambda c, k: flat.evaluate(c, k, env, acfg)))
    return init, jax.jit(chunk, donate_argnums=0), evaluate


def _mean_per_seed(metrics: dict) -> dict:
    """Chunk metrics ``[S, episodes]`` -> per-seed means ``[S]``."""
    return {k: np.asarray(v).reshape(v.shape[0], -1).mean(1) for k, v in metrics.items()}


def train(cfg: TrainConfig, *, progress: bool = True) -> list[dict]:
    """Run ``cfg``; returns the metric rows (also written to ``cfg.out``/metrics.csv)."""
    validate(cfg)
    if cfg.out:
        prepare_out(cfg)
    init, chunk, evaluate = build(cfg)
    key = jax.random.PRNGKey(cfg.seed)
    seed_keys = jax.random.split(key, cfg.seeds)
    carry = init(seed_keys)
    eval_key = jax.random.fold_in(key, 1)
    n_chunks = cfg.steps // cfg.steps_per_chunk
    rows: list[dict] = []
    bar = _progress(n_chunks, cfg) if progress else None
    t_start = time.perf_counter()
    for i in range(n_chunks):
        t0 = time.perf_counter()
        carry, metrics = chunk(carry, jnp.int32(i * cfg.episodes_per_chunk))
        ev = evaluate(carry, jax.random.split(jax.random.fold_in(eval_key, i), cfg.seeds))
        train_m, ev = _mean_per_seed(metrics), jax.tree.map(np.asarray, ev)
        dt = time.perf_counter() - t0
        step = (i + 1) * cfg.steps_per_chunk
        for s in range(cfg.seeds):
            rows.append({
                "step": step, "seed": s,
                "success_rate": float(ev["success_rate"][s]),
                "final_goal_distance": float(ev["final_goal_distance"][s]),
                "falls": int(ev["falls"][s]),
                "final_torso_z": float(ev["final_torso_z"][s]),
                "random_goal_success": float(ev["random_goal_success"][s]),
                "random_goal_distance": float(ev["random_goal_distance"][s]),
                "critic_loss": float(train_m["critic_loss"][s]),
                "q": float(train_m["q"][s]),
                "train_success": float(train_m["train_success"][s]),
                "wall_time": time.perf_counter() - t_start,
                "env_steps_per_s": cfg.seeds * cfg.steps_per_chunk / dt,
            })
        if cfg.out:
            _append_rows(cfg.out, rows[-cfg.seeds:])
        if bar is not None:
            bar.set_postfix(success=f"{ev['success_rate'].mean():.2f}",
                            steps_per_s=f"{rows[-1]['env_steps_per_s']:,.0f}")
            bar.update(1)
    if bar is not None:
        bar.close()
    return rows


def _progress(n_chunks: int, cfg: TrainConfig):
    from tqdm import tqdm

    return tqdm(total=n_chunks, unit="chunk", desc=f"{cfg.algo} {cfg.env} x{cfg.seeds} seeds",
                file=sys.stderr, dynamic_ncols=True)


def prepare_out(cfg: TrainConfig) -> None:
    """Create ``cfg.out`` with config.json; refuse a directory that holds another run."""
    os.makedirs(cfg.out, exist_ok=True)
    path = os.path.join(cfg.out, "config.json")
    if os.path.exists(path):
        with open(path) as f:
            old = json.load(f).get("config", {})
        diff = sorted(k for k, v in dataclasses.asdict(cfg).items() if old.get(k) != v)
        raise ConfigError(f"--out {cfg.out} already holds a run"
                          + (f" with a different config ({', '.join(diff)})" if diff else "")
                          + "; choose another --out")
    import mujoco

    with open(path, "w") as f:
        json.dump({"config": dataclasses.asdict(cfg),
                   "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__},
                   "device": str(jax.devices()[0].device_kind)}, f, indent=1)
    with open(os.path.join(cfg.out, "metrics.csv"), "w", newline="") as f:
        csv.writer(f).writerow(METRIC_FIELDS)


def _append_rows(out: str, rows: list[dict]) -> None:
    with open(os.path.join(out, "metrics.csv"), "a", newline="") as f:
        w = csv.DictWriter(f, METRIC_FIELDS)
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())


def parse_args(argv: list[str] | None = None) -> TrainConfig:
    """CLI flags -> a validated :class:`TrainConfig` (exits with a one-line error if bad)."""
    p = argparse.ArgumentParser(prog="python -m flrjax.train", description=__doc__.split("\n")[0])
    p.add_argument("--env", default=TrainConfig.env, help=f"one of {', '.join(envs.names())}")
    p.add_argument("--algo", default=TrainConfig.algo, help=f"one of {', '.join(ALGOS)}")
    p.add_argument("--preset", choices=["auto", *PRESETS], default="auto",
                   help="defaults for the sizes below: quick on a CPU, paper on a GPU (auto)")
    p.add_argument("--seeds", type=int, default=1, help="seeds trained at once (vmapped)")
    p.add_argument("--seed", type=int, default=0, help="base random seed")
    for name, typ in (("steps", int), ("num_envs", int), ("updates_per_step", float),
                      ("episodes_per_chunk", int), ("eval_episodes", int), ("batch_size", int),
                      ("hidden", int), ("buffer_episodes", int), ("initial_episodes", int),
                      ("episode_length", int)):
        p.add_argument("--" + name.replace("_", "-"), type=typ, default=None)
    p.add_argument("--out", default=None, help="run directory (default runs/<env>-<algo>-<time>)")
    try:
        args = p.parse_args(argv)
    except SystemExit as e:  # argparse already printed its one-line usage error
        raise SystemExit(e.code) from None
    preset = args.preset
    if preset == "auto":
        preset = "quick" if jax.default_backend() == "cpu" else "paper"
    kw = dict(PRESETS[preset])
    for k, v in vars(args).items():
        if k != "preset" and v is not None:
            kw[k] = v
    if kw.get("out") is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        kw["out"] = os.path.join("runs", f"{kw['env']}-{kw['algo']}-{stamp}")
    cfg = TrainConfig(**kw)
    try:
        validate(cfg)
    except ConfigError as e:
        p.error(str(e))
    return cfg


def main(argv: list[str] | None = None) -> None:
    cfg = parse_args(argv)
    try:
        rows = train(cfg)
    except ConfigError as e:
        print(f"python -m flrjax.train: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    last = [r for r in rows if r["step"] == rows[-1]["step"]]
    sr = np.array([r["success_rate"] for r in last])
    print(f"done: {cfg.steps:,} env steps x {cfg.seeds} seeds in {rows[-1]['wall_time']:.0f} s; "
          f"final success {sr.mean():.2f} +- {sr.std():.2f}; results in {cfg.out}/metrics.csv")


if __name__ == "__main__":
    main()
