"""Wall time of a paper-length run (one method x 5 seeds): extrapolated from measured speeds,
and measured where a committed training run got that far.

Reads the throughput the committed GPU measurements found (benchmark JSONs and the training
runs' ``env_steps_per_s``) and divides the budget by it; the extrapolation leaves out
compile time (under two minutes), and for the benchmark rows evaluations too. A training run
that reached the budget also gives ``measured_minutes``: its ``wall_time`` there, compiles
and evaluations included. The budget is an argument because the paper's text does not state
its x-axis length.

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


#: committed training runs (experiments/results/...) whose speeds and wall times are read
TRAINING_RUNS = ("dhrl_ant4leg", "ant3leg_dhrl_vs_flr_dhrl/dhrl",
                 "ant3leg_dhrl_vs_flr_dhrl/flr_dhrl", "ant3leg_pig_vs_flr_pig/pig",
                 "ant3leg_pig_vs_flr_pig/flr_pig")


def _run_speed(run_dir: str, budget: int) -> tuple[float, float | None, dict]:
    """Median env-steps/s (all seeds) over a run's chunks after the first (compile), the
    run's wall time in seconds at ``budget`` steps per seed (None if it stopped earlier), and
    its saved ``config.json``."""
    with open(os.path.join(ROOT, run_dir, "metrics.csv")) as f:
        rows = list(csv.DictReader(f))
    speeds = sorted({float(r["env_steps_per_s"]) for r in rows[1:]})
    reached = [float(r["wall_time"]) for r in rows if int(r["step"]) >= budget]
    return (speeds[len(speeds) // 2], min(reached) if reached else None,
            _json(os.path.join(run_dir, "config.json")))


def measurements(budget: int) -> list[dict]:
    """(what, protocol, seeds, env-steps/s over all seeds, device, source, and the measured
    wall time at ``budget`` steps per seed where a run has one) of every measurement."""
    out = []
    paper = _json("benchmarks/results/train_throughput/ant4leg_static_schedule.json")
    for r in paper["rows"]:
        if r["envs_per_seed"] == 1:
            out.append(dict(method="flat", env="ant4leg", seeds=r["seeds"],
                            protocol="paper: 1 env, 1 update/step",
                            steps_per_s=r["full_env_steps_per_s"], device=paper["device"],
                            source="train_throughput/ant4leg_static_schedule.json"))
    fast = _json("benchmarks/results/train_throughput/ant4leg_hierarchical_5x16.json")
    r = fast["rows"][0]
    for algo in fast["algos"]:
        key = "full_env_steps_per_s" if algo == "flat" else f"{algo}_full_env_steps_per_s"
        out.append(dict(method=algo, env="ant4leg", seeds=r["seeds"],
                        protocol="fast: 16 envs, 0.25 updates/step (benchmark)",
                        steps_per_s=r[key], device=fast["device"],
                        source="train_throughput/ant4leg_hierarchical_5x16.json"))
    for run in TRAINING_RUNS:
        speed, wall, saved = _run_speed(os.path.join("experiments", "results", run), budget)
        cfg = saved["config"]
        out.append(dict(method=cfg["algo"], env=cfg["env"], seeds=cfg["seeds"],
                        protocol=f"fast: {cfg['num_envs']} envs, {cfg['updates_per_step']:g} "
                                 "updates/step (training run)",
                        steps_per_s=speed, device=saved["device"],
                        source=f"experiments/results/{run}",
                        measured_minutes=None if wall is None else wall / 60))
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=1_200_000, help="env steps per seed")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    rows = measurements(args.steps)
    for r in rows:
        r["budget_steps_per_seed"] = args.steps
        r["extrapolated_minutes"] = args.steps * r["seeds"] / r["steps_per_s"] / 60
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"benchmark": "time_to_paper",
                       "note": "extrapolated_minutes: from measured speeds, compile and "
                               "evaluation time left out; measured_minutes: a training run's "
                               "wall time at the budget, everything included",
                       "rows": rows}, f, indent=1)
    print(f"{args.steps:,} env steps per seed, one GPU per run")
    print(f"{'method':>9} {'env':>8} {'seeds':>5} {'steps/s':>9} {'extrap. min':>11} "
          f"{'measured min':>12}  device, protocol")
    for r in rows:
        measured = r.get("measured_minutes")
        print(f"{r['method']:>9} {r['env']:>8} {r['seeds']:>5} {r['steps_per_s']:>9,.0f} "
              f"{r['extrapolated_minutes']:>11.1f} "
              f"{'-' if measured is None else f'{measured:.1f}':>12}  "
              f"{r['device']}, {r['protocol']}")


if __name__ == "__main__":
    main()
