"""Launch time through the command line: seconds from starting ``python -m flrjax.train`` until
the run's first metrics.csv row is written (its first chunk trained and evaluated), with an
empty compilation cache and again with the cache the first launch filled.

The launches, each a fresh process on the same cache, in this order:

- ``first``: a new run, the cache empty (unless ``--cache`` names a filled one);
- ``new_out``: the same flags, a new run directory;
- ``other_values``: with ``--vary`` appended (e.g. another learning rate), a new directory;
- ``resume``: ``--resume`` of ``new_out``'s directory.

Each launch is sent SIGTERM once its first row is written, so it stops cleanly after the chunk
in flight, with a checkpoint (the one ``resume`` continues from): ``--flags`` needs ``--steps``
of at least three chunks. Reported per launch: ``first_row_s``; ``start_line_s`` (import,
flags, the start line printed); the trainer's own ``first_chunk_s`` and
``chunk_compile_s`` (its progress line: the first chunk, and JAX's compile seconds in it),
with the line after it (``compiles``: the launch's compile log); and, from JAX's compile log
up to the first row, seconds of tracing, of XLA compiles (persistent-cache misses) and of
loads from the cache (hits), with the programs compiled and loaded, each with its seconds
(the trainer's stored ones run as ``jit_call``), and the trainer's warnings (e.g. a program
it could not store for the next launch).

    python benchmarks/launch_time.py --flags "--env ant3leg --seeds 5 --steps 240000" \\
        --vary "--lr-critic 5e-4" --out benchmarks/results/launch_time/h100_cli.json
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time

from flrjax import metrics_io

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: How often the run's metrics.csv is read for a new row (seconds).
POLL_S = 0.02
TRACED = re.compile(r"Finished tracing (?:\+ transforming )?(\S+) for p?jit in ([\d.e-]+) s")
COMPILED = re.compile(r"Finished XLA compilation of jit\((\S+)\) in ([\d.e-]+) s")
HIT = re.compile(r"Persistent compilation cache hit for '(\S+)'")
#: The trainer's line after its first chunk: the launch's compile log (launch_cache.compile_log).
COMPILES = "compiles so far:"
FIRST_CHUNK = re.compile(r"first chunk: ([\d.]+) s, ([\d.]+) s of it tracing and compiling")


def _rows(path: str) -> list[dict]:
    """metrics.csv's complete rows (none if absent, or while a new run writes its header)."""
    try:
        with open(path) as f:
            rows = csv.DictReader(f)
            if "step" not in (rows.fieldnames or ()):
                return []
            return [r for r in rows if None not in r.values()]
    except FileNotFoundError:
        return []


def _last_step(out: str) -> int:
    rows = _rows(os.path.join(out, "metrics.csv"))
    return max((int(r["step"]) for r in rows), default=0)


def _lines(stream, into: list, t0: float) -> None:
    """Append ``(seconds since t0, line)`` for each line of ``stream`` (tqdm's ``\\r`` too)."""
    for line in stream:
        into.append((time.perf_counter() - t0, line.rstrip("\n")))


def compile_log(lines: list[tuple[float, str]], until: float) -> dict:
    """JAX's compile log (``JAX_LOG_COMPILES``) up to ``until`` seconds: seconds of tracing, of
    XLA compiles (no persistent-cache hit before them) and of cache loads (hits), and the
    programs compiled and loaded, each with its seconds."""
    hits, out = set(), {"trace_s": 0.0, "compile_s": 0.0, "cache_load_s": 0.0,
                        "cache_hits": 0, "compiled": [], "loaded": []}
    for t, line in lines:
        if t > until:
            break
        if m := TRACED.search(line):
            out["trace_s"] += float(m[2])
        elif m := HIT.search(line):
            hits.add(m[1])
            out["cache_hits"] += 1
        elif m := COMPILED.search(line):
            name = f"jit_{m[1]}"
            if name in hits:
                hits.discard(name)
                out["cache_load_s"] += float(m[2])
                out["loaded"].append([name, round(float(m[2]), 3)])
            else:
                out["compile_s"] += float(m[2])
                out["compiled"].append([name, round(float(m[2]), 3)])
    return {k: round(v, 3) if isinstance(v, float) else v for k, v in out.items()}


def launch(name: str, args: list[str], out: str, cache: str, timeout: float) -> dict:
    """One ``python -m flrjax.train`` process: seconds to its first new metrics.csv row, then
    SIGTERM and wait for its clean stop."""
    env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": cache, "JAX_LOG_COMPILES": "1",
           "PYTHONPATH": os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH")) if p)}
    command = [sys.executable, "-m", "flrjax.train", *args]
    before = _last_step(out)
    t0 = time.perf_counter()
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=ROOT)
    stdout, stderr = [], []
    readers = [threading.Thread(target=_lines, args=(s, into, t0), daemon=True)
               for s, into in ((proc.stdout, stdout), (proc.stderr, stderr))]
    for r in readers:
        r.start()
    first_row = None
    while first_row is None and proc.poll() is None and time.perf_counter() - t0 < timeout:
        if _last_step(out) > before:
            first_row = time.perf_counter() - t0
        else:
            time.sleep(POLL_S)
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)  # stops after the chunk in flight, checkpointed
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    for r in readers:
        r.join()
    if first_row is None:
        raise SystemExit(f"launch {name} wrote no row ({proc.returncode}):\n"
                         + "\n".join(line for _, line in (stdout + stderr)[-15:]))
    start = next((t for t, line in stdout if line.strip()), None)
    chunk = next((FIRST_CHUNK.search(line) for _, line in stderr if FIRST_CHUNK.search(line)),
                 None)
    return {"launch": name, "command": "python -m flrjax.train " + shlex.join(args),
            "first_row_s": round(first_row, 2),
            "start_line_s": None if start is None else round(start, 2),
            "first_chunk_s": chunk and float(chunk[1]),
            "chunk_compile_s": chunk and float(chunk[2]),
            **compile_log(stderr, first_row), "exit": proc.returncode,
            "warnings": [line for _, line in stderr if "flrjax.train: warning" in line],
            "compiles": next((line.strip() for _, line in stderr if COMPILES in line), None),
            "start_line": next((line for _, line in stdout if line.strip()), None)}


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--flags", required=True,
                   help="the trainer's flags, --steps of three chunks or more, no --out")
    p.add_argument("--vary", default=None,
                   help="flags appended for the other_values launch (e.g. '--lr-critic 5e-4'); "
                        "none: no such launch")
    p.add_argument("--cache", default=None, help="compilation cache (default: a fresh one)")
    p.add_argument("--runs", default=None, help="where the run directories go (default: temp)")
    p.add_argument("--timeout", type=float, default=1800, help="seconds per launch")
    p.add_argument("--out", default=None, help="JSON")
    args = p.parse_args(argv)
    cache = args.cache or tempfile.mkdtemp(prefix="flrjax-launch-cache-")
    runs = args.runs or tempfile.mkdtemp(prefix="flrjax-launch-runs-")
    flags = shlex.split(args.flags)
    dirs = {name: os.path.join(runs, name) for name in ("first", "new_out", "other_values")}
    plan = [("first", flags), ("new_out", flags)]  # (launch, its flags but --out)
    if args.vary:
        plan.append(("other_values", [*flags, *shlex.split(args.vary)]))
    plan = [(name, [*f, "--out", dirs[name]], dirs[name]) for name, f in plan]
    plan.append(("resume", ["--resume", dirs["new_out"]], dirs["new_out"]))
    result = {"benchmark": "launch_time", "mode": "cli", "flags": args.flags,
              "vary": args.vary, **metrics_io.git_state(), "cpus": os.cpu_count(),
              "command": "python benchmarks/launch_time.py " + shlex.join(
                  sys.argv[1:] if argv is None else argv), "launches": []}
    for name, f, out in plan:
        r = launch(name, f, out, cache, args.timeout)
        result["launches"].append(r)
        result["start_line"] = result["launches"][0]["start_line"]
        print(f"{r['launch']}: first row {r['first_row_s']:.1f} s (start line "
              f"{r['start_line_s']:.1f} s; tracing {r['trace_s']:.1f} s, compiling "
              f"{r['compile_s']:.1f} s, cache loads {r['cache_load_s']:.1f} s)"
              + "".join(f"\n  {x}" for x in [r["compiles"], *r["warnings"]] if x), flush=True)
        if args.out:  # after each launch: a cut benchmark keeps the launches it made
            metrics_io.write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
