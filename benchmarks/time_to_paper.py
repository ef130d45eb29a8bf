"""Wall time of a paper-length run (one method x 5 seeds), extrapolated from measured speeds.

Reads the throughput the committed GPU measurements found (benchmark JSONs and the training
runs' ``env_steps_per_s``) and divides the budget by it. Extrapolated, not run: compile time
(under a minute) and evaluations are left out, and the budget is an argument because the
paper's text does not state its x-axis length.

    python benchmarks/time_to_paper.py --steps 1200000 --out benchmarks/results/time_to_paper.json
"""

from __future__ import annotations

import argparse
import csv
import json
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _json(path: str) -> dict:
    with open(os.path.join(ROOT, path)) as f:
        return json.load(f)


def _run_speed(run_dir: str) -> tuple[float, dict]:
    """Median env-steps/s (all seeds) over a run's chunks after the first (compile), with
    the run's config."""
    with open(os.path.join(ROOT, run_dir, "metrics.csv")) as f:
        rows = list(csv.DictReader(f))
    speeds = sorted({float(r["env_steps_per_s"]) for r in rows[1:]})
    return speeds[len(speeds) // 2], _json(os.path.join(run_dir, "config.json"))["config"]


def measurements() -> list[dict]:
    """(what, protocol, seeds, env-steps/s over all seeds, source) of every measurement."""
    out = []
    paper = _json("benchmarks/results/train_throughput/ant4leg_static_schedule.json")
    for r in paper["rows"]:
        if r["envs_per_seed"] == 1:
            out.append(dict(method="flat", env="ant4leg", seeds=r["seeds"],
                            protocol="paper: 1 env, 1 update/step",
                            steps_per_s=r["full_env_steps_per_s"],
                            source="train_throughput/ant4leg_static_schedule.json"))
    fast = _json("benchmarks/results/train_throughput/ant4leg_hierarchical_5x16.json")
    r = fast["rows"][0]
    for algo in fast["algos"]:
        key = "full_env_steps_per_s" if algo == "flat" else f"{algo}_full_env_steps_per_s"
        out.append(dict(method=algo, env="ant4leg", seeds=r["seeds"],
                        protocol="fast: 16 envs, 0.25 updates/step (benchmark)",
                        steps_per_s=r[key],
                        source="train_throughput/ant4leg_hierarchical_5x16.json"))
    for run in ("dhrl_ant4leg", "dhrl_ant3leg", "flr_dhrl_ant3leg"):
        speed, cfg = _run_speed(os.path.join("experiments", "results", run))
        out.append(dict(method=cfg["algo"], env=cfg["env"], seeds=cfg["seeds"],
                        protocol=f"fast: {cfg['num_envs']} envs, {cfg['updates_per_step']:g} "
                                 "updates/step (training run)",
                        steps_per_s=speed, source=f"experiments/results/{run}"))
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=1_200_000, help="env steps per seed")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    rows = measurements()
    for r in rows:
        r["budget_steps_per_seed"] = args.steps
        r["extrapolated_minutes"] = args.steps * r["seeds"] / r["steps_per_s"] / 60
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"benchmark": "time_to_paper", "device": "NVIDIA H100 80GB HBM3",
                       "note": "extrapolated from measured speeds; compile and evaluation "
                               "time left out", "rows": rows}, f, indent=1)
    print(f"{args.steps:,} env steps per seed, extrapolated from measurements on one H100")
    print(f"{'method':>9} {'env':>8} {'seeds':>5} {'steps/s':>9} {'minutes':>8}  protocol")
    for r in rows:
        print(f"{r['method']:>9} {r['env']:>8} {r['seeds']:>5} {r['steps_per_s']:>9,.0f} "
              f"{r['extrapolated_minutes']:>8.1f}  {r['protocol']}")


if __name__ == "__main__":
    main()
