"""Recompute results.md's throughput table from this folder's files and print it.

Each program NAME left NAME_metrics.csv (per-chunk ``env_steps_per_s`` of all runs together,
``wall_time``), NAME_config.json (card, resolved kernels), NAME.log (first line: the command
with CUDA_VISIBLE_DEVICES) and NAME.times (launch and first-chunk wall clocks of the shell
that started it; where it has no first-chunk clock, as for ``G_*``, the log's own
``first chunk: N s``, counted from the trainer's start). Usage: ``python table.py``.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _times(path: Path) -> dict[str, float]:
    """``launch``/``first_chunk``/``end`` epoch seconds from a NAME.times file."""
    return {line.split()[0]: float(line.split()[1]) for line in path.read_text().splitlines()}


def row(name: str) -> dict:
    """One program's numbers: runs, GPUs, card, chunk 2's env steps/s, launch to chunk 1."""
    rows = list(csv.DictReader((HERE / f"{name}_metrics.csv").open()))
    steps = sorted({int(r["step"]) for r in rows})
    second = [r for r in rows if int(r["step"]) == steps[1]]
    first = [r for r in rows if int(r["step"]) == steps[0]]
    config = json.loads((HERE / f"{name}_config.json").read_text())
    log = (HERE / f"{name}.log").read_text()
    command = log.splitlines()[0]
    gpus = len(re.search(r"CUDA_VISIBLE_DEVICES=(\S+)", command).group(1).split(","))
    t = _times(HERE / f"{name}.times")
    if "first_chunk" not in t:
        t["first_chunk"] = t["launch"] + float(re.search(r"first chunk: (\d+) s", log).group(1))
    rate = float(second[0]["env_steps_per_s"])
    return {"name": name, "runs": len(second), "gpus": gpus, "card": config["device"],
            "commit": config["git"]["commit"][:7], "chunk": steps[1] - steps[0],
            "kernel": config["resolved"]["flr_value_kernel"], "rate": rate,
            "per_run": rate / len(second),
            "chunk2_s": float(second[0]["wall_time"]) - float(first[0]["wall_time"]),
            "launch_to_first_s": t["first_chunk"] - t["launch"]}


def main() -> None:
    names = sorted(p.name.removesuffix("_metrics.csv") for p in HERE.glob("*_metrics.csv"))
    rows = sorted((row(n) for n in names), key=lambda r: (r["commit"] != "73fbc0f", r["gpus"],
                                                             r["runs"]))
    print("| runs per program | GPUs | card | commit | env steps per seed per chunk "
          "| env steps/s (chunk 2, all runs) | per run | chunk 2 wall (s) "
          "| launch to first chunk (s) | eq. 5 kernel | program |")
    print("|---:|---:|---|---|---:|---:|---:|---:|---:|---|---|")
    for r in rows:
        print(f"| {r['runs']} | {r['gpus']} | {r['card']} | {r['commit']} | {r['chunk']:,} | "
              f"{r['rate']:,.0f} | "
              f"{r['per_run']:,.0f} | {r['chunk2_s']:.1f} | {r['launch_to_first_s']:.0f} | "
              f"{r['kernel']} | {r['name']} |")


if __name__ == "__main__":
    main()
