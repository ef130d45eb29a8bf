"""Run several trainer configurations one after another and collect their metrics in one CSV.

Each variant is ``NAME=FLAGS``: the flags are added to ``--base`` and passed to
``python -m flrjax.train``. Each run's metrics go to ``OUT/NAME.csv``, all configs and wall
times to ``OUT/grid.json``. Meant for ablations and sweeps on one device, with few output
files::

    python experiments/run_grid.py --out results/sweep --base "--env point4leg --seeds 4" \\
        flat="--algo flat" dhrl="--algo dhrl"

With ``--time-limit SECONDS`` the grid stops cleanly before the limit: the run in progress
checkpoints into ``--runs`` (default ``runs/grid/<name of OUT>``; kept out of the results
because the replay buffers make checkpoints large) and its CSV so far is written. Running the
same command again skips the finished runs, resumes the cut one and goes on, so a grid can
span jobs of a cluster's (or a device lease's) time limit. Several processes (one per GPU,
say, each with its own ``CUDA_VISIBLE_DEVICES`` and a different subset of variants) can
share one ``OUT``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import shlex
import shutil
import time

import jax

from flrjax import train


def records(out: str) -> dict[str, dict]:
    """The runs recorded in ``out``/grid.json, by name."""
    path = os.path.join(out, "grid.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return {r["run"]: r for r in json.load(f)}


def _record(out: str, record: dict) -> None:
    """Add or replace ``record`` in grid.json; re-read first and replace atomically, so
    processes sharing ``out`` keep each other's records."""
    merged = {**records(out), record["run"]: record}
    tmp = os.path.join(out, f".grid.json.{os.getpid()}")
    with open(tmp, "w") as f:
        json.dump(list(merged.values()), f, indent=1)
    os.replace(tmp, os.path.join(out, "grid.json"))


def _fresh_or_resume(cfg: train.TrainConfig) -> bool:
    """Whether ``cfg.out`` holds a checkpoint of this very run to resume. A directory with a
    different config is refused; one without a checkpoint yet is cleared (nothing to keep)."""
    path = os.path.join(cfg.out, "config.json")
    if not os.path.exists(path):
        return False
    with open(path) as f:
        saved = json.load(f)["config"]
    if saved != train.config_dict(cfg):
        raise SystemExit(f"run_grid: {cfg.out} holds a run with another config; "
                         "remove it or choose another --runs")
    if train.has_checkpoint(cfg.out):
        return True
    shutil.rmtree(cfg.out)
    return False


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", default="", help="flags common to every variant")
    p.add_argument("--out", required=True, help="directory for NAME.csv and grid.json")
    p.add_argument("--runs", default=None,
                   help="run directories with checkpoints (default runs/grid/<name of --out>)")
    p.add_argument("--time-limit", type=float, default=None, metavar="SECONDS",
                   help="stop cleanly before SECONDS; the same command again continues")
    p.add_argument("variants", nargs="+", help="NAME=FLAGS")
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    runs_root = args.runs or os.path.join(
        "runs", "grid", os.path.basename(os.path.normpath(args.out)))
    deadline = None if args.time_limit is None else time.perf_counter() + args.time_limit
    for v in args.variants:
        name, _, flags = v.partition("=")
        cfg, _, _ = train.parse_cli([*shlex.split(args.base), *shlex.split(flags),
                                     "--out", os.path.join(runs_root, name),
                                     "--checkpoint-every", "0"])
        config = train.config_dict(dataclasses.replace(cfg, out=None))
        old = records(args.out).get(name)
        if old and old["config"] == config and old["steps_done"] == cfg.steps:
            print(f"{name}: finished before, skipped", flush=True)
            continue
        left = None if deadline is None else deadline - time.perf_counter()
        if left is not None and left <= 0:
            print(f"time limit: {name} not started; run the same command again", flush=True)
            break
        rows = train.train(cfg, resume=_fresh_or_resume(cfg), time_limit=left)
        with open(os.path.join(args.out, f"{name}.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, train.csv_fields(cfg))
            w.writeheader()
            w.writerows(rows)
        done = rows[-1]["step"]
        _record(args.out, {"run": name, "flags": f"{args.base} {flags}".strip(),
                           "wall_s": rows[-1]["wall_time"], "steps_done": done,
                           "device": str(jax.devices()[0].device_kind), "config": config})
        last = [r for r in rows if r["step"] == done]
        sr = [r["success_rate"] for r in last]
        print(f"{name}: {done:,} of {cfg.steps:,} steps, {rows[-1]['wall_time']:.0f} s, "
              f"success {sum(sr) / len(sr):.2f} ({', '.join(f'{x:.1f}' for x in sr)})",
              flush=True)
        if done < cfg.steps:
            print(f"time limit: {name} checkpointed in {cfg.out}; run the same command again "
                  "to continue", flush=True)
            break


if __name__ == "__main__":
    main()
