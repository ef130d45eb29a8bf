"""Launch time: seconds from a process's start until a run's programs are compiled and it can
start its first training chunk, with an empty persistent compilation cache and again with the
cache the first launch filled. (The trainer compiles the evaluation while the first chunk runs,
so the first chunk can start once init and the chunk are ready.)

Each launch is a fresh Python process that imports flrjax, builds the run's config (trainer
flags in ``--flags``), and compiles its init, chunk and evaluation (``time_to_result.
compile_ahead``: the trainer's own jitted functions, so the cache entries are the ones a
training run loads). Reported per launch: import, each program's build-and-compile seconds,
``first_chunk_s`` (process start until init and the chunk are ready) and total seconds.
The trainer stores its traced programs beside the cache (:mod:`flrjax.launch_cache`), so a
later launch neither traces nor compiles them; ``FLRJAX_PROGRAM_CACHE=0`` measures the
compilation cache alone.

    python benchmarks/launch_time.py --flags "--env ant3leg --algo flr_dhrl --seeds 5 \\
        --flr-alpha 0,0.01 --num-envs 16 --updates-per-step 0.25 --episodes-per-chunk 5" \\
        --out benchmarks/results/launch_time/h100.json
"""

from __future__ import annotations

import time

T_LAUNCH = time.perf_counter()

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import shlex  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def launch(flags: str, cache: str) -> dict:
    """In this process: import, build and compile; seconds since the process started."""
    import jax

    from flrjax import cli, runner

    sys.path.insert(0, HERE)
    from time_to_result import compile_ahead

    imported = time.perf_counter() - T_LAUNCH
    runner.enable_compile_cache(cache)
    cfg = cli.parse_cli([*shlex.split(flags), "--out", tempfile.mkdtemp()]).cfg
    seconds = compile_ahead(cfg)
    return {"import_s": imported, "build_compile_s": sum(seconds.values()),
            "program_s": seconds,
            "first_chunk_s": imported + seconds["init"] + seconds["chunk"],
            "total_s": time.perf_counter() - T_LAUNCH, "device": jax.devices()[0].device_kind}


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--flags", required=True, help="the trainer's flags")
    p.add_argument("--cache", default=None, help="compilation cache (default: a fresh one)")
    p.add_argument("--launches", type=int, default=2, help="the first one cold")
    p.add_argument("--out", default=None, help="JSON")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(launch(args.flags, args.cache)))
        return {}
    cache = args.cache or tempfile.mkdtemp(prefix="flrjax-launch-cache-")
    runs = []
    for i in range(args.launches):
        child = subprocess.run([sys.executable, os.path.abspath(__file__), "--child",
                                "--flags", args.flags, "--cache", cache],
                               capture_output=True, text=True)
        if child.returncode:  # the launch's own error, not only its exit status
            raise SystemExit(f"launch {i + 1} failed ({child.returncode}):\n"
                             + "\n".join(child.stderr.strip().splitlines()[-15:]))
        runs.append(json.loads(child.stdout.strip().splitlines()[-1]))
        r = runs[-1]
        print(f"launch {i + 1}: import {r['import_s']:.1f} s, init {r['program_s']['init']:.1f}"
              f" s, chunk {r['program_s']['chunk']:.1f} s (first chunk can start at "
              f"{r['first_chunk_s']:.1f} s), evaluation {r['program_s']['evaluate']:.1f} s, "
              f"total {r['total_s']:.1f} s", flush=True)
    result = {"benchmark": "launch_time", "device": runs[0]["device"], "flags": args.flags,
              "command": "python benchmarks/launch_time.py " + " ".join(
                  shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv)),
              "launches": runs}
    if args.out:
        os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    return result


if __name__ == "__main__":
    main()
