"""Run several trainer configurations one after another and collect their metrics in one CSV.

Each variant is ``NAME=FLAGS``: the flags are added to ``--base`` and passed to
``python -m flrjax.train``. Each run's metrics go to ``OUT/NAME.csv``, all configs and wall
times to ``OUT/grid.json``; runs keep no checkpoints. Meant for ablations and sweeps on one
device, with few output files::

    python experiments/run_grid.py --out results/sweep --base "--env point4leg --seeds 4" \\
        flat="--algo flat" dhrl="--algo dhrl"
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import shlex
import tempfile
import time

import jax

from flrjax import train


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", default="", help="flags common to every variant")
    p.add_argument("--out", required=True, help="directory for grid.csv and grid.json")
    p.add_argument("variants", nargs="+", help="NAME=FLAGS")
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    runs = []
    for v in args.variants:
        name, _, flags = v.partition("=")
        with tempfile.TemporaryDirectory() as tmp:
            cfg, _, _ = train.parse_cli([*shlex.split(args.base), *shlex.split(flags),
                                      "--out", os.path.join(tmp, name),
                                      "--checkpoint-every", "0"])
            t0 = time.perf_counter()
            rows = train.train(cfg)
            wall = time.perf_counter() - t0
        runs.append({"run": name, "flags": f"{args.base} {flags}".strip(), "wall_s": wall,
                     "device": str(jax.devices()[0].device_kind),
                     "config": dataclasses.asdict(dataclasses.replace(cfg, out=None))})
        with open(os.path.join(args.out, f"{name}.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, train.metric_fields(cfg.algo))
            w.writeheader()
            w.writerows(rows)
        with open(os.path.join(args.out, "grid.json"), "w") as f:
            json.dump(runs, f, indent=1)
        last = [r for r in rows if r["step"] == rows[-1]["step"]]
        sr = [r["success_rate"] for r in last]
        print(f"{name}: {wall:.0f} s, final success {sum(sr) / len(sr):.2f} "
              f"({', '.join(f'{x:.1f}' for x in sr)})", flush=True)


if __name__ == "__main__":
    main()
