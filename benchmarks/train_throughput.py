"""Env-steps/s of full training steps against raw physics, with a breakdown of where the time
goes, for seeds x envs-per-seed configurations under two update protocols.

Protocols (updates per env step):
- ``paper``: 1, the reference's protocol (one update per env step);
- ``fast``: 1 / envs, i.e. one update per vectorised iteration per seed: the data grows with
  the envs, the updates do not;
- a number: that many updates per env step (our training runs use 0.25 with 16 envs).

Measures:
- ``physics``: raw ``mjx.step`` x frame_skip, scanned, at the same batch (seeds x envs);
- ``flat_noupd``: the flat chunk with random actions and no updates (physics + act + store),
  and, on the buffer it filled, the chunk's updates alone (HER sampling included; any method
  with a :attr:`~flrjax.algos.registry.Method.learn_alone`, as ``ALGO_noupd``);
- ``flat``, ``dhrl``, ``flr_dhrl``, ...: the full training chunk of that ``--algo``.

From them, per config, the fractions of the ``flr_dhrl`` step: physics, act/store
(flat_noupd - physics), updates with HER relabelling (flat - flat_noupd), planning and high
level (dhrl - flat) and FLR (flr_dhrl - dhrl); differences of separately timed chunks, so
approximate. Graph methods rebuild their graph every episode round (the reference rebuilds
every 9,000 env steps), which overstates the rebuild's share.

Gradient updates/s (``*_updates_per_s``): env steps/s x updates per env step, summed over
seeds; one update is one low-level gradient step of one seed on a batch of 1,024 (graph
methods add one high-level step per 10 of them, as the reference does).

Memory: what XLA's compiled chunk needs (arguments + outputs - donated + temporaries).

Compiling dominates a grid's wall time. ``--jobs N`` first compiles every job in N parallel
processes into a persistent compilation cache (``--cache``); the jobs are then timed one after
the other in this process, loading their executables from the cache. Results are written
after every job; rerunning the same command with the same ``--out`` skips the jobs already
in it. ``SxE:PROTOCOL:M1+M2`` gives a config its own protocol and measures.

    python benchmarks/train_throughput.py --env ant4leg --configs 5x16:fast,5x16:paper \\
        --measures physics,flat_noupd,flat,dhrl,flr_dhrl --jobs 8 --out RESULT.json
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import os
import platform
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import mujoco

from flrjax import algos, config, runner, validation

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from env_throughput import bench_env  # noqa: E402

REPEATS = 2  # default timed calls after the compiling one; the fastest counts
PROTOCOLS = ("paper", "fast")
TOP = ("flr_dhrl", "dhrl", "flat")  # a row's headline step: the first of these it has
NO_UPDATES = "_noupd"  # ``ALGO_noupd``: that method's chunk acting at random, no updates
#: The ``flr_dhrl`` step's parts: each measure less the one before it (physics first).
LADDER = (("physics", "physics"), ("act_store", "flat_noupd"), ("updates_her", "flat"),
          ("planning_high_level", "dhrl"), ("flr", "flr_dhrl"))


def acts_only(measure: str) -> bool:
    """Whether ``measure`` times physics or acting alone (no training step to shard)."""
    return measure == "physics" or measure.endswith(NO_UPDATES)


def updates_per_step(protocol: str, num_envs: int) -> float:
    """Gradient updates per env step of ``protocol`` (a name, or the number itself) at
    ``num_envs`` envs per seed."""
    if protocol in PROTOCOLS:
        return 1.0 if protocol == "paper" else 1.0 / num_envs
    try:
        return float(protocol)
    except ValueError:
        raise ValueError(f"unknown protocol {protocol!r}: {PROTOCOLS} or a number of "
                         "updates per env step") from None


def job_config(job: dict) -> config.TrainConfig:
    """The trainer config a job times: batch 1024, 3x256 MLPs, one episode round per chunk."""
    measure = job["measure"]
    algo = {} if measure == "physics" else {"algo": measure.removesuffix(NO_UPDATES)}
    envs, length = job["envs"], job["episode_length"]
    cfg = config.TrainConfig(
        env=job["env"], **algo, seeds=job["seeds"], num_envs=envs, steps=envs * length,
        updates_per_step=updates_per_step(job["protocol"], envs), episodes_per_chunk=1,
        batch_size=1024, hidden=256, buffer_episodes=max(2 * envs, 50), initial_episodes=0,
        episode_length=length, devices=job.get("devices", 1))
    if "graph_start_steps" in config.run_flags(cfg):  # the graph rebuilt every round
        cfg = cfg.replace(graph_start_steps=0, graph_every_steps=envs * length)
    if measure.endswith(NO_UPDATES):
        cfg = cfg.replace(initial_episodes=10**9)  # random actions, no updates
    if job.get("value_chunk") is not None:  # only FLR jobs carry it (see parse_jobs)
        cfg = cfg.replace(flr_value_chunk=job["value_chunk"])
    validation.validate(cfg)
    return cfg


def time_chunk(cfg: config.TrainConfig, warm: bool = False, repeats: int = REPEATS):
    """(first call seconds (compile included), fastest of ``repeats`` further calls, carry,
    GiB the compiled chunk needs: arguments + outputs - donated + temporaries), with the seeds
    sharded over ``cfg.devices``. With ``warm`` the chunk is only compiled (times are NaN)."""
    init, chunk, _ = runner.build(cfg)
    carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
    t0 = time.perf_counter()
    compiled = chunk.lower(carry, jnp.int32(0)).compile()
    first = time.perf_counter() - t0
    if warm:
        return first, float("nan"), carry, float("nan")
    mem = compiled.memory_analysis()
    gib = (mem.argument_size_in_bytes + mem.output_size_in_bytes - mem.alias_size_in_bytes
           + mem.temp_size_in_bytes) / 2**30 if mem else float("nan")
    times = []
    for i in range(1 + repeats):
        t0 = time.perf_counter()
        carry, m = compiled(carry, jnp.int32(i))
        jax.block_until_ready(m)
        times.append(time.perf_counter() - t0)
    return first + times[0], min(times[1:]), carry, gib


def time_updates(cfg: config.TrainConfig, carry, iters: int, warm: bool = False,
                 repeats: int = REPEATS):
    """(first call seconds, fastest further call) of ``iters`` iterations' updates alone:
    the method's :attr:`~flrjax.algos.registry.Method.learn_alone` on the buffer in ``carry``."""
    method = algos.get(cfg.algo)
    acfg = method.from_run(cfg, config.make_env(cfg))
    keys = jax.random.split(jax.random.PRNGKey(1), cfg.seeds)
    t0 = time.perf_counter()
    run = jax.jit(jax.vmap(lambda c, k: method.learn_alone(c, k, iters, acfg))).lower(
        carry, keys).compile()
    if warm:
        return time.perf_counter() - t0, float("nan")
    times = []
    for _ in range(1 + repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(run(carry, keys))
        times.append(time.perf_counter() - t0)
    return times[0], min(times[1:])


def run_job(job: dict, warm: bool) -> dict:
    """Time (or, with ``warm``, only compile) one measure; ms per vectorised iteration."""
    cfg, iters, repeats = job_config(job), job["episode_length"], job.get("repeats", REPEATS)
    if job["measure"] == "physics":
        env = config.make_env(cfg)
        out = {"ms_per_iter": float("nan")}  # the point mass has no MJX physics
        if hasattr(env, "sys"):
            r = bench_env(env, cfg.seeds * cfg.num_envs, 50, 1 if warm else 3,
                          jax.random.PRNGKey(0))
            out = {"ms_per_iter": r["raw_ms_per_step"], "first_call_s": r["compile_s_raw"]}
    elif job["measure"].endswith(NO_UPDATES):
        first, best, carry, gib = time_chunk(cfg, warm, repeats)  # buffer holds the rounds
        u_first, u_best = time_updates(dataclasses.replace(cfg, initial_episodes=0), carry,
                                       iters, warm, repeats)
        out = {"ms_per_iter": 1e3 * best / iters, "first_call_s": first, "chunk_gib": gib,
               "updates_alone_ms_per_iter": 1e3 * u_best / iters, "updates_first_call_s": u_first}
    else:
        first, best, _, gib = time_chunk(cfg, warm, repeats)
        out = {"ms_per_iter": 1e3 * best / iters, "first_call_s": first, "chunk_gib": gib}
    return out


def _compile_in_subprocess(job: dict, cache: str) -> dict:
    """Compile ``job``'s executables into the persistent ``cache`` in a fresh process."""
    env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": cache,
           "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
           # exact allocations: parallel compiles must not hold each other's memory
           "XLA_PYTHON_CLIENT_ALLOCATOR": "platform"}
    p = subprocess.run([sys.executable, os.path.abspath(__file__), "--job", json.dumps(job)],
                       env=env, capture_output=True, text=True)
    lines = [s for s in p.stdout.splitlines() if s.startswith("RESULT ")]
    if p.returncode or not lines:
        return {"error": (p.stderr or p.stdout).strip().splitlines()[-1:]}
    return json.loads(lines[-1][len("RESULT "):])


def parse_jobs(args: argparse.Namespace) -> list[dict]:
    """Jobs for every config x protocol x measure (``SxE:PROTOCOL:M1+M2`` overrides both)."""
    jobs = []
    for spec in args.configs.split(","):
        size, proto, measures = (spec.split(":") + ["", ""])[:3]
        seeds, envs = (int(x) for x in size.split("x"))
        for protocol in [proto] if proto else args.protocols.split(","):
            if protocol == "fast" and envs == 1 and not proto:
                continue  # one env: the fast protocol is the paper protocol
            for m in (measures.split("+") if measures else args.measures.split(",")):
                measure, _, devices = m.partition("@")
                if devices and acts_only(measure):
                    raise SystemExit(f"{m}: only training steps are sharded over devices")
                if measure.endswith(NO_UPDATES) and algos.get(
                        measure.removesuffix(NO_UPDATES)).learn_alone is None:
                    raise SystemExit(f"{m}: {measure.removesuffix(NO_UPDATES)} has no "
                                     "updates-alone step (Method.learn_alone)")
                jobs.append({"env": args.env, "seeds": seeds, "envs": envs,
                             "protocol": protocol, "measure": measure,
                             "devices": int(devices or 1),
                             "episode_length": args.episode_length,
                             "repeats": args.repeats})
                # only when given, and only where it applies: the jobs of earlier results
                # (and of runs without the flag) stay as they were
                if args.value_chunk is not None and measure in config.takers("flr_value_chunk"):
                    jobs[-1]["value_chunk"] = args.value_chunk
    return jobs


def measure_name(job: dict) -> str:
    """The job's measure, with ``@N`` for a step sharded over N devices."""
    n = job.get("devices", 1)
    return job["measure"] + (f"@{n}" if n > 1 else "")


def job_key(job: dict) -> str:
    """``SxE:PROTOCOL:MEASURE[@N]``."""
    return "{seeds}x{envs}:{protocol}:".format(**job) + measure_name(job)


def other_value_chunk(jobs: list[dict], done: dict[str, dict]) -> list[str]:
    """Keys of ``jobs`` that ``done`` (an --out file's jobs) timed with another --value-chunk:
    job keys leave it out, so such a job would be skipped as done."""
    return [job_key(j) for j in jobs if job_key(j) in done
            and done[job_key(j)].get("job", {}).get("value_chunk") != j.get("value_chunk")]


def summarise(results: dict[str, dict]) -> list[dict]:
    """One row per (config, protocol): ms/iter and env-steps/s of each measure, fractions."""
    rows: dict[tuple, dict] = {}
    alone: dict[tuple, str] = {}  # per row: the method whose updates were timed alone
    for r in results.values():
        if "error" in r:
            continue
        job = r["job"]
        key = (job["seeds"], job["envs"], job["protocol"])
        row = rows.setdefault(key, {
            "seeds": job["seeds"], "envs_per_seed": job["envs"], "protocol": job["protocol"],
            "batch": job["seeds"] * job["envs"],
            "updates_per_step": updates_per_step(job["protocol"], job["envs"])})
        m = measure_name(job)
        row[f"{m}_ms_per_iter"] = r["ms_per_iter"]
        row[f"{m}_env_steps_per_s"] = 1e3 * row["batch"] / r["ms_per_iter"]
        if not acts_only(job["measure"]):  # summed over seeds
            row[f"{m}_updates_per_s"] = row[f"{m}_env_steps_per_s"] * row["updates_per_step"]
        row[f"{m}_chunk_gib"] = r.get("chunk_gib", float("nan"))
        row[f"{m}_compile_s"] = r.get("compile_s", float("nan"))
        if "updates_alone_ms_per_iter" in r:
            row["updates_alone_ms_per_iter"] = r["updates_alone_ms_per_iter"]
            alone[key] = job["measure"].removesuffix(NO_UPDATES)
    for key, row in rows.items():
        ms = {m: row.get(f"{m}_ms_per_iter") for _, m in LADDER}
        top = next((m for m in TOP if ms[m]), None)
        if top and ms["physics"]:
            row[f"{top}_fraction_of_raw_physics"] = ms["physics"] / ms[top]
        method = alone.get(key)
        if method and row.get(f"{method}_ms_per_iter") and ms["physics"]:
            row[f"{method}_over_physics_plus_updates"] = row[f"{method}_ms_per_iter"] / (
                ms["physics"] + row["updates_alone_ms_per_iter"])
        for k in [k for k in row if "@" in k and k.endswith("_ms_per_iter")]:
            m = k[:-len("_ms_per_iter")]
            if f"{m.split('@')[0]}_ms_per_iter" in row:
                row[f"{m}_speedup"] = row[f"{m.split('@')[0]}_ms_per_iter"] / row[k]
        if all(ms.values()):
            below = [0.0] + [ms[m] for _, m in LADDER[:-1]]
            row["flr_dhrl_breakdown"] = {part: (ms[m] - b) / ms[LADDER[-1][1]]
                                         for (part, m), b in zip(LADDER, below, strict=True)}
    return sorted(rows.values(), key=lambda r: (r["protocol"], r["envs_per_seed"], r["seeds"]))


def print_table(result: dict) -> None:
    print(f"\n{result['env']}, {result['device']}, batch 1024, 3x256 MLPs, "
          f"{result['episode_length']}-step episodes; ms per vectorised iteration")
    cols = tuple(m for _, m in LADDER)
    print(f"{'config':>14} " + " ".join(f"{c:>10}" for c in cols)
          + f" {'top steps/s':>12} {'top upd/s':>10} {'top/raw':>8} {'chunk GiB':>9}")
    for r in result["rows"]:
        top = next((m for m in TOP if f"{m}_ms_per_iter" in r), None)
        frac = r.get(f"{top}_fraction_of_raw_physics", float("nan")) if top else float("nan")
        sps = r.get(f"{top}_env_steps_per_s", float("nan")) if top else float("nan")
        ups = r.get(f"{top}_updates_per_s", float("nan")) if top else float("nan")
        peak = r.get(f"{top}_chunk_gib", float("nan")) if top else float("nan")
        print(f"{r['seeds']:>4}x{r['envs_per_seed']:<4}{r['protocol']:>6} "
              + " ".join(f"{r.get(f'{c}_ms_per_iter', float('nan')):>10.2f}" for c in cols)
              + f" {sps:>12,.0f} {ups:>10,.0f} {frac:>8.2f} {peak:>9.2f}")


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="ant4leg")
    p.add_argument("--configs", default="1x1,5x1,5x16,50x16,5x256",
                   help="SEEDSxENVS[:PROTOCOL],...")
    p.add_argument("--protocols", default="paper,fast",
                   help="for configs without their own; fast at 1 env is skipped (= paper)")
    p.add_argument("--measures", default="physics,flat_noupd,flat,dhrl,flr_dhrl")
    p.add_argument("--episode-length", type=int, default=80)
    p.add_argument("--repeats", type=int, default=REPEATS,
                   help="timed calls after the first (a chunk's first call starts from an "
                        "empty buffer, so it is never the one timed); 1 for update-bound rows "
                        "whose chunk takes minutes")
    p.add_argument("--value-chunk", type=int, default=None,
                   help="flr_* measures: reaching transitions per V evaluation chunk (the "
                        "trainer's --flr-value-chunk; default: its 128; 0: the whole batch). "
                        "Job keys leave it out: time each value into its own --out file")
    p.add_argument("--jobs", type=int, default=1,
                   help="parallel processes that compile every job into --cache first")
    p.add_argument("--cache", default="runs/jax_cache", help="persistent compilation cache")
    p.add_argument("--time-limit", type=float, default=float("inf"),
                   help="seconds after which no new job starts")
    p.add_argument("--out", default=None, help="JSON; jobs already in it are skipped")
    p.add_argument("--job", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.repeats < 1:
        p.error("--repeats must be at least 1")
    if args.value_chunk is not None and args.value_chunk < 0:
        p.error("--value-chunk must be >= 0 (0: the whole batch)")
    if args.job:  # compile one job, in its own process
        print("RESULT " + json.dumps(run_job(json.loads(args.job), warm=True)), flush=True)
        return
    jax.config.update("jax_compilation_cache_dir", args.cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    t_start = time.perf_counter()
    jobs = parse_jobs(args)
    for job in jobs:
        job_config(job)  # fail fast on a config the trainer refuses
    result = {"benchmark": "train_throughput", "command": "python " + " ".join(sys.argv),
              "device": str(jax.devices()[0].device_kind),
              "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__,
                           "python": platform.python_version()},
              "env": args.env, "episode_length": args.episode_length, "jobs": {}}
    if args.out and os.path.exists(args.out):
        with open(args.out) as f:
            result["jobs"] = {k: v for k, v in json.load(f)["jobs"].items() if "error" not in v}
    if clash := other_value_chunk(jobs, result["jobs"]):
        p.error(f"--out {args.out} holds {', '.join(clash)} timed with another --value-chunk; "
                "give this run another --out")
    todo = [j for j in jobs if job_key(j) not in result["jobs"]]

    def left() -> float:
        return args.time_limit - (time.perf_counter() - t_start)

    def save() -> None:
        result["rows"] = summarise(result["jobs"])
        if args.out:
            with open(args.out, "w") as f:
                json.dump(result, f, indent=1)

    compile_s: dict[str, float] = {}
    if args.jobs > 1 and todo:
        with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
            futs = {pool.submit(lambda j: _compile_in_subprocess(j, args.cache) if left() > 0
                                else {"error": "time limit"}, j): j for j in todo}
            for fut in concurrent.futures.as_completed(futs):
                r = fut.result()
                compile_s[job_key(futs[fut])] = r.get("first_call_s", float("nan"))
                print(f"compiled {job_key(futs[fut])}: {r}", flush=True)
    for job in todo:
        if left() <= 0:
            print(f"time limit: {job_key(job)} and later jobs not run", flush=True)
            break
        try:
            r = run_job(job, warm=False)
        except Exception as e:  # noqa: BLE001 - a failed job is recorded, the grid goes on
            r = {"error": f"{type(e).__name__}: {e}"}
        r["job"] = job
        # the warm phase's time is the compile (under --jobs parallel compiles); without it
        # first_call_s is compile + one call, or a cache load if an earlier run compiled it
        r["compile_s"] = compile_s.get(job_key(job), float("nan"))
        result["jobs"][job_key(job)] = r
        print(f"{job_key(job)}: {r}", flush=True)
        save()
    save()
    print_table(result)


if __name__ == "__main__":
    main()
