"""Paper-protocol rows too slow to time, extrapolated from the ones that were, and checked
against the measured ones.

Under the paper protocol (one update per env step) an iteration of E envs per seed makes E
updates per seed, so its time is about ``a + b * (E - 1)``: ``a`` the one-env iteration
(physics, acting, planning and one update), ``b`` one more update. Fitted per device and seed
count on the measured 1- and 16-env rows of ``train_throughput.py`` results, the line gives
the other env counts; where a row was also measured the table shows both. At 100 seeds x 256
envs one 40-iteration chunk (the shortest the ant's subgoal period allows) makes 10,240
updates per seed, more than a 10-minute device call can time.

    python benchmarks/paper_protocol_fit.py --out benchmarks/results/paper_protocol_fit.json
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT = os.path.join(ROOT, "benchmarks", "results", "train_throughput", "ant4leg_h100*.json")
MEASURE = "flr_dhrl"  # the grid's headline step


def measured(paths: list[str]) -> dict[tuple, dict]:
    """(device, seeds, envs) -> {ms, source} of every paper-protocol ``MEASURE`` row in
    ``paths``; the last file listing a row wins (the default's names sort oldest first)."""
    out: dict[tuple, dict] = {}
    for path in paths:
        with open(path) as f:
            result = json.load(f)
        for r in result.get("rows", []):
            ms = r.get(f"{MEASURE}_ms_per_iter")
            key = (result["device"], r["seeds"], r["envs_per_seed"])
            if r["protocol"] == "paper" and ms:
                out[key] = {"ms": ms, "source": os.path.relpath(path, ROOT)}
    return out


def fit(rows: dict[tuple, dict], envs: tuple[int, ...]) -> list[dict]:
    """Per (device, seeds) with 1- and 16-env rows: ms per iteration at each of ``envs`` from
    the line through them, env steps/s, and the measured ms and relative error where known."""
    table = []
    for device, seeds in sorted({(d, s) for d, s, _ in rows}):
        one, sixteen = rows.get((device, seeds, 1)), rows.get((device, seeds, 16))
        if not (one and sixteen):
            continue
        per_update = (sixteen["ms"] - one["ms"]) / 15
        for e in envs:
            ms = one["ms"] + per_update * (e - 1)
            row = {"device": device, "seeds": seeds, "envs_per_seed": e,
                   "predicted_ms_per_iter": ms, "ms_per_update": per_update,
                   "predicted_env_steps_per_s": 1e3 * seeds * e / ms}
            if (device, seeds, e) in rows:
                got = rows[(device, seeds, e)]
                row.update(measured_ms_per_iter=got["ms"], source=got["source"],
                           relative_error=ms / got["ms"] - 1)
            table.append(row)
    return table


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("inputs", nargs="*", help=f"train_throughput JSONs (default: {DEFAULT})")
    p.add_argument("--envs", default="1,16,256", help="env counts per seed to give")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    paths = args.inputs or sorted(glob.glob(DEFAULT))
    table = fit(measured(paths), tuple(int(e) for e in args.envs.split(",")))
    print(f"{MEASURE}, paper protocol: ms per iteration = a + b (E - 1)")
    print(f"{'device':>24} {'seeds':>5} {'envs':>5} {'fitted ms':>10} {'measured':>9} "
          f"{'error':>7} {'env steps/s':>12}")
    for r in table:
        got = r.get("measured_ms_per_iter", float("nan"))
        err = 100 * r.get("relative_error", float("nan"))
        print(f"{r['device']:>24} {r['seeds']:>5} {r['envs_per_seed']:>5} "
              f"{r['predicted_ms_per_iter']:>10.1f} {got:>9.1f} {err:>6.1f}% "
              f"{r['predicted_env_steps_per_s']:>12,.0f}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"benchmark": "paper_protocol_fit", "measure": MEASURE,
                       "command": "python benchmarks/paper_protocol_fit.py "
                       + " ".join(sys.argv[1:] if argv is None else argv),
                       "inputs": [os.path.relpath(q, ROOT) for q in paths], "rows": table},
                      f, indent=1)


if __name__ == "__main__":
    main()
