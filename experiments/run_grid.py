"""Run several trainer configurations and collect their metrics in one CSV each.

Each variant is ``NAME=FLAGS``: the flags are added to ``--base`` and passed to
``python -m flrjax.train``. Each run's metrics go to ``OUT/NAME.csv``, all configs and wall
times to ``OUT/grid.json``. Meant for ablations and sweeps, with few output files::

    python experiments/run_grid.py --out results/sweep --base "--env point4leg --seeds 4" \\
        flat="--algo flat" dhrl="--algo dhrl"

On a host with several GPUs the variants run side by side, each as its own process on its own
GPU (``--gpus 0,1,2,3`` to choose them; default CUDA_VISIBLE_DEVICES, else every GPU
``nvidia-smi -L`` lists; ``--gpus-per-program N`` for more than one each), its output in
``RUNS/logs/NAME.log``; a failed one is reported and the others go on. With one GPU or none
they run one after the other in this process. ``--submitit slurm`` submits each variant as a
SLURM job through submitit (``pip install 'flrjax[cluster]'``) and waits for them, e.g. from a
cluster's login node::

    python experiments/run_grid.py --out results/sweep --base "--env ant3leg" \\
        --submitit slurm --slurm-partition gpu --time-limit 14000 \\
        --slurm-param account=myproj flat="--algo flat" dhrl="--algo dhrl"

each job getting ``--gpus-per-program`` GPUs and ``--time-limit`` and a few minutes of SLURM
time, its files in ``RUNS/submitit/``. (``--submitit local``: submitit's local executor, on
this host's GPUs.)

With ``--time-limit SECONDS`` each run stops cleanly before the limit: the run in progress
checkpoints into ``--runs`` (default ``runs/grid/<name of OUT>``; kept out of the results
because the replay buffers make checkpoints large) and its CSV so far is written. Running the
same command again skips the finished runs, resumes the cut ones and goes on, so a grid can
span jobs of a cluster's time limit. Several processes (one per host, say, each with a
different subset of variants) can share one ``OUT``.

``--adopt DIR,DIR,...`` (one variant) takes finished standalone runs (``python -m
flrjax.train --out DIR``) as the variant's sweep points instead of training it: each DIR's
config must be one point's (a base method's run counting as its FLR version's α = 0 point,
eq. 5 with α = 0 being eq. 1), all seeds alike, and the CSV is cut at the step all of them
reached. grid.json records where the rows came from, and later commands skip the variant::

    python experiments/run_grid.py --out results/fig5 --base "--env ant3leg --seeds 5" \
        --adopt runs/dhrl,runs/flr_dhrl dhrl="--algo flr_dhrl --flr-alpha 0,0.01"
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import fcntl
import json
import os
import shlex
import shutil
import sys
import time

import jax

from flrjax import algos, metrics_io
from flrjax.analysis import plural
from flrjax.checkpoint import has_checkpoint
from flrjax.cli import parse_cli
from flrjax.config import SHARED, TrainConfig, point_name, sweep_fields, sweep_points
from flrjax.launch_cache import enable_compile_cache
from flrjax.metrics_io import config_dict
from flrjax.options import flags_of
from flrjax.runner import metric_fields, train
from flrjax.stops import Stopped

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import launch  # noqa: E402


def records(out: str) -> dict[str, dict]:
    """The runs recorded in ``out``/grid.json, by name."""
    path = os.path.join(out, "grid.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return {r["run"]: r for r in json.load(f)}


def record(out: str, entry: dict) -> None:
    """Add or replace ``entry`` (by its ``run``) in grid.json: under an exclusive lock of the
    directory ``out`` itself (no lock file to leave behind), re-read it and replace it
    atomically, so that processes sharing ``out`` (one per GPU) keep each other's records."""
    fd = os.open(out, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # released when the descriptor closes
        merged = {**records(out), entry["run"]: entry}
        tmp = os.path.join(out, f".grid.json.{os.getpid()}")
        with open(tmp, "w") as f:
            json.dump(list(merged.values()), f, indent=1)
        os.replace(tmp, os.path.join(out, "grid.json"))
    finally:
        os.close(fd)


def _fresh_or_resume(cfg: TrainConfig) -> bool:
    """Whether ``cfg.out`` holds a checkpoint of this very run to resume. A directory with a
    different config is refused; one without a checkpoint yet is cleared (nothing to keep)."""
    path = os.path.join(cfg.out, "config.json")
    if not os.path.exists(path):
        return False
    with open(path) as f:
        saved = json.load(f)["config"]
    if saved != config_dict(cfg):
        raise SystemExit(f"run_grid: {cfg.out} holds a run with another config; "
                         "remove it or choose another --runs")
    if has_checkpoint(cfg.out):
        return True
    shutil.rmtree(cfg.out)
    return False


def _write_csv(out: str, name: str, cfg: TrainConfig, rows: list[dict]) -> None:
    with open(os.path.join(out, f"{name}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, metric_fields(cfg))
        w.writeheader()
        w.writerows(rows)


def _point_config(config: dict) -> dict:
    """A run's config as a sweep point compares it: a base method's run as the sweep point of
    the method built on it (:attr:`flrjax.algos.Method.base`: DHRL as FLR+DHRL's α = 0 point,
    that method's other flags unset), unset sweepable flags at their values, and what does not
    change its numbers (output, planned steps, checkpoints, devices and the FLR value chunk:
    tests show that sharding and chunking do not) left out."""
    c = dict(config)
    over = [m for m in algos.methods() if m.base == c["algo"]]
    if over:
        c["algo"] = over[0].name
        for f in dataclasses.fields(over[0].options):
            c.setdefault(f.name, f.default)
        c.update(dict(over[0].base_point))
    for k, f in sweep_fields().items():
        if k in c and c[k] is None:
            c[k] = f.default
    return {k: v for k, v in c.items()
            if k not in ("out", "steps", "sweep", "checkpoint_every", "devices", "flr_value_chunk")}


def adopt(cfg: TrainConfig, dirs: list[str]) -> tuple[list[dict], list[dict]]:
    """The rows of ``cfg``'s sweep points taken from the finished runs ``dirs`` (one per
    point, any order), cut at the step every run reached, as ``cfg``'s own CSV would hold
    them, and what each run was (dir, device, steps reached). Refuses a run that is no point
    of ``cfg``, or a run whose config.json lacks a field that applies to it."""
    points = sweep_points(cfg)
    want = [_point_config(config_dict(cfg.replace(**p, sweep=None))) for p in points]
    found: dict[int, tuple[str, str, list[dict]]] = {}  # point -> (dir, device, rows)
    for d in dirs:
        with open(os.path.join(d, "config.json")) as f:
            saved = json.load(f)
        got = _point_config(saved["config"])
        takes = {*SHARED, *flags_of(algos.get(saved["config"]["algo"]).options)}
        missing = [k for k in want[0] if k not in saved["config"] and k in takes]
        if missing:
            raise SystemExit(f"run_grid: {d} predates {', '.join(missing)}; it cannot stand "
                             "for a run of today's code")
        got = {k: got.get(k, v) for k, v in want[0].items()}
        if got not in want:
            diff = sorted(k for k in got if all(got[k] != w.get(k) for w in want))
            raise SystemExit(f"run_grid: {d} is none of the sweep points of {cfg.algo} "
                             f"{point_name(points[0])}...: differs in {', '.join(diff)}")
        i = want.index(got)
        if i in found:
            raise SystemExit(f"run_grid: {found[i][0]} and {d} are the same sweep point")
        with open(os.path.join(d, "metrics.csv")) as f:
            found[i] = (d, saved.get("device", ""), list(csv.DictReader(f)))
    if len(found) != len(points):
        raise SystemExit(f"run_grid: {plural(len(points), 'sweep point')}, "
                         f"{plural(len(found), 'run')} to adopt")
    reached = {i: max(int(r["step"]) for r in rows) for i, (_, _, rows) in found.items()}
    cut = min(reached.values())
    fields = metric_fields(cfg)
    rows = [{k: ({**r, **points[i]}).get(k, "") for k in fields}
            for i in range(len(points)) for r in found[i][2] if int(r["step"]) <= cut]
    rows.sort(key=lambda r: int(r["step"]))  # a run's order: by step, then point, then seed
    return rows, [{"dir": found[i][0], "point": points[i], "steps_reached": reached[i],
                   "device": found[i][1]} for i in range(len(points))]


def _skipped(out: str, name: str, config: dict, steps: int, adopting: bool) -> bool:
    """Whether variant ``name`` is left out: finished before with this config, or adopted
    (unless it is being adopted now). Says why."""
    old = records(out).get(name)
    if old and old["config"] == config and old["steps_done"] == steps:
        print(f"{name}: finished before, skipped", flush=True)
        return True
    if old and "adopted" in old and not adopting:
        print(f"{name}: adopted from {', '.join(s['dir'] for s in old['adopted'])}, "
              "skipped (remove its record from grid.json to train it)", flush=True)
        return True
    return False


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--base", default="", help="flags common to every variant")
    p.add_argument("--out", required=True, help="directory for NAME.csv and grid.json")
    p.add_argument("--runs", default=None,
                   help="run directories with checkpoints (default runs/grid/<name of --out>)")
    p.add_argument("--time-limit", type=float, default=None, metavar="SECONDS",
                   help="stop cleanly before SECONDS; the same command again continues")
    p.add_argument("--adopt", default=None, metavar="DIR,DIR,...",
                   help="take these finished runs as the (one) variant's sweep points")
    p.add_argument("variants", nargs="+", help="NAME=FLAGS")
    launch.add_arguments(p)
    args = p.parse_args(argv)
    if args.adopt and len(args.variants) != 1:
        p.error("--adopt takes the runs of one variant")
    os.makedirs(args.out, exist_ok=True)
    runs_root = args.runs or os.path.join(
        "runs", "grid", os.path.basename(os.path.normpath(args.out)))
    deadline = None if args.time_limit is None else time.perf_counter() + args.time_limit
    placed = not args.adopt and (args.submitit or launch.slots(args) is not None)
    if placed:
        launch.start_jax_without_preallocating()
    todo = []
    for v in args.variants:
        name, _, flags = v.partition("=")
        cli = parse_cli([*shlex.split(args.base), *shlex.split(flags),
                         "--out", os.path.join(runs_root, name), "--checkpoint-every", "0"])
        config = config_dict(dataclasses.replace(cli.cfg, out=None))
        if not _skipped(args.out, name, config, cli.cfg.steps, bool(args.adopt)):
            todo.append((name, flags, cli, config))
    if todo and placed:
        flags_of_run = {name: flags for name, flags, _, _ in todo}

        def command(name: str, left: float | None) -> list[str]:
            return [sys.executable, os.path.abspath(__file__), "--out", os.path.abspath(
                args.out), f"--base={args.base}", "--runs", os.path.abspath(runs_root),
                    *(["--time-limit", str(left)] if left is not None else []),
                    f"{name}={flags_of_run[name]}"]

        launch.run(list(flags_of_run), command, args, runs_root, deadline, args.time_limit)
        return
    for name, flags, cli, config in todo:
        cfg = cli.cfg
        enable_compile_cache(cli.compile_cache)
        if args.adopt:
            rows, sources = adopt(cfg, args.adopt.split(","))
            _write_csv(args.out, name, cfg, rows)
            record(args.out, {"run": name, "flags": f"{args.base} {flags}".strip(),
                              "wall_s": max(float(r["wall_time"]) for r in rows),
                              "steps_done": int(rows[-1]["step"]),
                              "device": " / ".join(sorted({s["device"] for s in sources})),
                              "config": config, "adopted": sources})
            print(f"{name}: adopted {plural(len(sources), 'run')}, cut at "
                  f"{int(rows[-1]['step']):,} steps", flush=True)
            continue
        left = None if deadline is None else deadline - time.perf_counter()
        if left is not None and left <= 0:
            print(f"time limit: {name} not started; run the same command again", flush=True)
            break
        try:
            rows = train(cfg, resume=_fresh_or_resume(cfg), time_limit=left)
        except Stopped as e:  # SIGINT or SIGTERM: the run is checkpointed; one line, no trace
            print(f"{name}: {e}; run the same command again to continue", file=sys.stderr)
            raise SystemExit(128 + e.signum) from None
        _write_csv(args.out, name, cfg, rows)
        done = rows[-1]["step"]
        record(args.out, {"run": name, "flags": f"{args.base} {flags}".strip(),
                          "wall_s": rows[-1]["wall_time"], "steps_done": done,
                          "device": str(jax.devices()[0].device_kind), "config": config,
                          "git": metrics_io.git_state(), "command": metrics_io.command_line()})
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
