"""Time to result: wall-clock seconds from launch, compiling included, until the seed-mean
evaluation success of FLR+DHRL first reaches a threshold, with DHRL trained beside it.

One training program: ``--algo flr_dhrl --flr-alpha 0,ALPHA`` (DHRL is the alpha = 0 sweep
point, vmapped with FLR+DHRL's seeds), plus the trainer flags given in ``--flags``. Each
chunk's evaluation gives one curve row per method (seconds since launch, env steps per seed,
mean and std of the success rate over seeds). The run stops at the chunk where FLR+DHRL's mean
first reaches ``--threshold``, or at ``--steps``; with ``--past-threshold`` it trains on to
``--steps`` (the full curves of both methods, in the run directory's metrics.csv).

A long run may be split over several calls: ``--time-limit`` stops it with a checkpoint in
``--run-dir``, and the same command continues it. The seconds of all calls add up (each call's
launch, compile or cache load and training), so a split run reports more than an unbroken
one would, never less.

The compile is timed apart: the chunk and evaluation are compiled ahead of the first call
into a persistent compilation cache (``--cache``, by default a fresh directory: a cold
compile), from which the trainer then loads them.

    python benchmarks/time_to_result.py --out benchmarks/results/time_to_result \\
        --flags "--env ant3leg --seeds 5 --preset tuned"

writes ``OUT/<device>.json`` (``device`` and ``devices``, how many the runs were split over,
``command``, ``threshold``, ``compile_s``, ``seconds_to_threshold`` and ``env_steps_to_threshold``
per method, null where not reached, ``curve``: per chunk its seconds of training and of
evaluation too) and ``OUT/<device>.png`` (success against seconds); ``<device>`` is e.g.
``h200``, or ``h200x2`` on two.
"""

from __future__ import annotations

import time

T_LAUNCH = time.perf_counter()  # before the imports: importing JAX is part of a launch

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import re  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402

import jax  # noqa: E402
import numpy as np  # noqa: E402

from flrjax import metrics_io  # noqa: E402
from flrjax.algos.common import num_devices  # noqa: E402
from flrjax.checkpoint import has_checkpoint  # noqa: E402
from flrjax.cli import parse_cli  # noqa: E402
from flrjax.config import TrainConfig  # noqa: E402
from flrjax.launch_cache import enable_compile_cache  # noqa: E402
from flrjax.metrics_io import config_dict  # noqa: E402
from flrjax.run_axis import shard_seeds  # noqa: E402
from flrjax.runner import build, train  # noqa: E402

#: Curve names of the two sweep points.
METHODS = ("dhrl", "flr_dhrl")


def device_slug(kind: str, backend: str, devices: int = 1) -> str:
    """A file name for the devices a run is split over: ``h100``, ``h200``, ``a100`` ... or
    ``cpu``, with ``x2``, ``x4`` ... for several (so that a measurement never continues, or
    overwrites, one made on another number of devices)."""
    if backend == "cpu":
        name = "cpu"
    else:
        m = re.search(r"\b([A-Z]\d{2,4})\b", kind)
        name = m.group(1).lower() if m else re.sub(r"[^a-z0-9]+", "_", kind.lower()).strip("_")
    return f"{name}x{devices}" if devices > 1 else name


def config(flags: str, alpha: float) -> TrainConfig:
    """The trainer's config: ``flags`` with DHRL (alpha 0) and FLR+DHRL (``alpha``) as one
    sweep, no checkpoint but at a time limit (unless ``flags`` ask for them: writing the
    replay costs seconds); its run directory is set once known (the trainer checks it)."""
    cli = parse_cli(["--checkpoint-every", "0", *shlex.split(flags), "--algo",
                     "flr_dhrl", "--flr-alpha", f"0,{alpha}"])
    return cli.cfg


def method_rows(rows: list[dict], seeds: int) -> dict[str, list[dict]]:
    """One chunk's metric rows (DHRL's seeds, then FLR+DHRL's) split by method."""
    return {m: rows[i * seeds:(i + 1) * seeds] for i, m in enumerate(METHODS)}


def curve_row(seconds: float, step: int, rows: list[dict], seeds: int) -> dict:
    """Seconds since launch, env steps per seed, the seconds of the chunk's training and of
    its evaluation, and each method's success over seeds (mean, sample std)."""
    out = {"seconds": seconds, "env_steps": step, "chunk_s": rows[0]["chunk_s"],
           "eval_s": rows[0]["eval_s"]}
    for m, rs in method_rows(rows, seeds).items():
        sr = np.array([r["success_rate"] for r in rs])
        out[m] = {"mean": float(sr.mean()), "std": float(sr.std(ddof=1)) if len(sr) > 1 else 0.0}
    return out


def first_reach(curve: list[dict], method: str, threshold: float) -> dict | None:
    """The first curve row where ``method``'s mean success is at least ``threshold``."""
    return next((r for r in curve if r[method]["mean"] >= threshold), None)


def compile_ahead(cfg: TrainConfig) -> dict[str, float]:
    """Compile the run's init, chunk and evaluation into the persistent cache, in the order the
    trainer needs them; seconds taken by each (tracing and lowering included). The trainer's
    own first calls then load them."""
    seconds, t0 = {}, time.perf_counter()
    init, chunk, evaluate = build(cfg)
    keys = jax.ShapeDtypeStruct((cfg.runs, 2), np.uint32, sharding=shard_seeds(cfg))
    carry = init.eval_shape(keys)
    carry = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype,
                                                        sharding=shard_seeds(cfg)), carry)
    init.lower(keys).compile()
    seconds["init"], t0 = time.perf_counter() - t0, time.perf_counter()
    chunk.lower(carry, np.int32(0)).compile()
    seconds["chunk"], t0 = time.perf_counter() - t0, time.perf_counter()
    evaluate.lower(carry, keys).compile()
    seconds["evaluate"] = time.perf_counter() - t0
    return seconds


def plot(result: dict, path: str) -> None:
    """Success against seconds since launch, mean and std band (clipped to [0, 1])."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.2))
    ax = fig.add_subplot()
    curve = result["curve"]
    t = np.array([r["seconds"] for r in curve])
    for m, label in zip(METHODS, ("DHRL", "FLR+DHRL"), strict=True):
        mean = np.array([r[m]["mean"] for r in curve])
        std = np.array([r[m]["std"] for r in curve])
        ax.plot(t, mean, label=label)
        ax.fill_between(t, np.clip(mean - std, 0, 1), np.clip(mean + std, 0, 1), alpha=0.2)
    ax.axhline(result["threshold"], color="gray", ls=":", lw=1)
    for i, call in enumerate(result["calls"]):
        ax.axvspan(call["start_s"], call["compiled_at_s"], color="gray", alpha=0.15, lw=0,
                   label="launch and compile" if i == 0 else None)
    ax.set_xlabel("seconds since launch (compile included)")
    ax.set_ylabel(f"evaluation success, mean ± std over {result['seeds']} seeds")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlim(0, None)
    n = result["devices"]
    ax.set_title(f"Time to result on {result['env']}, {f'{n} x ' if n > 1 else ''}"
                 f"{result['device']}", fontsize=10)
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--flags", default="--env ant3leg --seeds 5 --preset tuned",
                   help="the trainer's flags (not --algo / --flr-alpha)")
    p.add_argument("--alpha", type=float, default=0.01, help="FLR+DHRL's alpha")
    p.add_argument("--threshold", type=float, default=0.8)
    p.add_argument("--out", required=True, help="directory of <device>.json and .png")
    p.add_argument("--run-dir", default=None,
                   help="the run's checkpoints (default: runs/time_to_result/<device>)")
    p.add_argument("--cache", default=None,
                   help="persistent compilation cache (default: a fresh temporary one)")
    p.add_argument("--past-threshold", action="store_true",
                   help="train on to --steps after the threshold is reached")
    p.add_argument("--time-limit", type=float, default=None,
                   help="seconds of this call; the same command continues the run")
    args = p.parse_args(argv)
    dev = jax.devices()[0]
    cfg = config(args.flags, args.alpha)
    devices = num_devices(cfg)
    slug = device_slug(dev.device_kind, jax.default_backend(), devices)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"{slug}.json")
    prev = json.load(open(path)) if os.path.exists(path) else None
    if prev and (prev["finished"] or not has_checkpoint(prev["run_dir"])):
        prev = None  # a finished (or unresumable) measurement: start a new one
    run_dir = prev["run_dir"] if prev else (
        args.run_dir or tempfile.mkdtemp(prefix="flrjax-ttr-run-"))
    cfg = cfg.replace(out=run_dir)
    before = prev["calls"][-1]["end_s"] if prev else 0.0
    enable_compile_cache(args.cache or tempfile.mkdtemp(prefix="flrjax-ttr-cache-"))
    compile_s = sum(compile_ahead(cfg).values())
    compiled_at = before + time.perf_counter() - T_LAUNCH
    curve = list(prev["curve"]) if prev else []

    def progress(step: int, rows: list[dict]) -> bool:
        while curve and curve[-1]["env_steps"] >= step:  # trained again after the checkpoint
            curve.pop()
        curve.append(curve_row(before + time.perf_counter() - T_LAUNCH, step, rows,
                               cfg.seeds))
        c = curve[-1]
        print(f"{c['seconds']:8.1f} s  {step:>9,} steps  " + "  ".join(
            f"{m} {c[m]['mean']:.2f}±{c[m]['std']:.2f}" for m in METHODS), flush=True)
        return c["flr_dhrl"]["mean"] >= args.threshold and not args.past_threshold

    left = None if args.time_limit is None else max(
        args.time_limit - (time.perf_counter() - T_LAUNCH), 1e-3)
    train(cfg, progress=False, resume=prev is not None, time_limit=left,
          progress_fn=progress)
    end = before + time.perf_counter() - T_LAUNCH
    calls = [*(prev["calls"] if prev else []),
             {"start_s": before, "compiled_at_s": compiled_at, "end_s": end,
              "compile_s": compile_s}]
    reach = {m: first_reach(curve, m, args.threshold) for m in METHODS}
    result = {
        "benchmark": "time_to_result", "device": dev.device_kind, "devices": devices,
        "backend": jax.default_backend(),
        "jax": jax.__version__, **metrics_io.git_state(),
        "command": "python benchmarks/time_to_result.py " + " ".join(
            shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv)),
        "env": cfg.env, "seeds": cfg.seeds, "alpha": args.alpha, "threshold": args.threshold,
        "config": config_dict(cfg), "run_dir": run_dir,
        "compile_s": calls[0]["compile_s"],
        "seconds_to_threshold": {m: r and r["seconds"] for m, r in reach.items()},
        "env_steps_to_threshold": {m: r and r["env_steps"] for m, r in reach.items()},
        "finished": (bool(reach["flr_dhrl"]) and not args.past_threshold) or (
            bool(curve) and curve[-1]["env_steps"] >= cfg.steps),
        "calls": calls, "curve": curve,
    }
    with open(path, "w") as f:
        json.dump(result, f, indent=1)
    plot(result, os.path.join(args.out, f"{slug}.png"))
    print(f"compile {result['compile_s']:.1f} s; to {args.threshold}: " + ", ".join(
        f"{m} {s:.0f} s" if s is not None else f"{m} not reached"
        for m, s in result["seconds_to_threshold"].items()) + f"; {path}")
    return result


if __name__ == "__main__":
    main()
