"""Merge one run's seeds trained by several processes (one per GPU, say) into one run.

A run that must finish in a time limit can be split over GPUs by seed (a program of fewer
seeds takes less time per iteration, though not in proportion: few seeds are bound by
latency more than by arithmetic): the same flags with its own ``--seed`` per process, each a
``run_grid.py`` variant in one shared ``--out``. This joins those variants' CSVs into
``OUT/NAME.csv`` with the seeds renumbered in the order given (part 1's seeds first), cut at
the last step every part reached, and records in grid.json which part each seed came from::

    python experiments/merge_seeds.py --out results/paper_ratio dhrl=pair_5000,pair_5001

A part written elsewhere (another ``--out``, another day's run) is named by its path,
``DIR/RUN``: its CSV and its record in ``DIR``/grid.json are first copied into ``--out``, so
that the merged run's folder holds every part it was made from::

    python experiments/merge_seeds.py --out results/paper_ratio \
        dhrl=pair_5000,pair_5001,/tmp/day2/pair_5002

The merged CSV has the columns every part has (the others are listed in the record; each
part's CSV keeps its own). The parts' configs must agree in everything but the seed, and their
seeds must differ;
``--allow FIELD,...`` lets them differ in more fields, which the merged record lists with each
part's value (e.g. a learner number an older commit recorded as None, its default then, that a
newer one records resolved: check by hand that the values agree, and say so).
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run_grid  # noqa: E402

from flrjax.analysis import plural  # noqa: E402

#: Config fields the parts of one run may differ in (the seed, and where each was written).
PER_PART = ("seed", "seeds", "out")


def adopt(out: str, part: str) -> str:
    """The run name of ``part``: ``part`` itself, or for a path ``DIR/RUN`` the run ``RUN``
    of ``DIR``, whose CSV and grid.json record are copied into ``out`` first. Refuses a run
    that ``out`` already records otherwise."""
    src, run = os.path.split(os.path.normpath(part))
    if not src or os.path.abspath(src) == os.path.abspath(out):
        return run
    rec = run_grid.records(src).get(run)
    if rec is None:
        raise SystemExit(f"merge_seeds: no record of {run} in {src}/grid.json")
    here = run_grid.records(out).get(run)
    if here is not None and here != rec:
        raise SystemExit(f"merge_seeds: {out} already records another {run}")
    os.makedirs(out, exist_ok=True)
    shutil.copyfile(os.path.join(src, f"{run}.csv"), os.path.join(out, f"{run}.csv"))
    run_grid.record(out, rec)
    return run


def _columns(path: str) -> list[str]:
    with open(path) as f:
        return next(csv.reader(f))


def merge(out: str, name: str, parts: list[str], allow: tuple[str, ...] = ()) -> dict:
    """Write ``out``/``name``.csv from the runs ``parts`` recorded in ``out``/grid.json (or
    given as ``DIR/RUN``: :func:`adopt`) and record it there; returns the record. Refuses
    parts that are not one run's seeds, unless they differ only in the fields ``allow``."""
    parts = [adopt(out, p) for p in parts]
    recs = run_grid.records(out)
    missing = [p for p in parts if p not in recs]
    if missing:
        raise SystemExit(f"merge_seeds: no record of {', '.join(missing)} in {out}/grid.json")
    if len(parts) < 2 or name in parts:
        raise SystemExit("merge_seeds: name two or more parts, none of them the merged run")
    configs = [recs[p]["config"] for p in parts]
    shared = [{k: v for k, v in c.items() if k not in (*PER_PART, *allow)} for c in configs]
    for p, c in zip(parts[1:], shared[1:], strict=True):
        if c != shared[0]:
            diff = sorted(k for k in {*c, *shared[0]} if c.get(k, ...) != shared[0].get(k, ...))
            raise SystemExit(f"merge_seeds: {p} differs from {parts[0]} in {', '.join(diff)}")
    seeds = [c["seed"] for c in configs]
    if len(set(seeds)) != len(seeds):
        raise SystemExit(f"merge_seeds: the parts share a seed ({seeds})")
    cut = min(recs[p]["steps_done"] for p in parts)
    columns = [_columns(os.path.join(out, f"{p}.csv")) for p in parts]
    header = [k for k in columns[0] if all(k in cols for cols in columns)]
    dropped = sorted({k for cols in columns for k in cols} - set(header))
    rows, offset, points = [], 0, {}
    for p, c in zip(parts, configs, strict=True):
        with open(os.path.join(out, f"{p}.csv")) as f:
            for r in csv.DictReader(f):
                if int(r["step"]) <= cut:
                    rows.append({**{k: r[k] for k in header},
                                 "seed": str(offset + int(r["seed"]))})
        offset += c["seeds"]
    sweep = [k for k in header[2:] if k in configs[0]]  # the swept fields' columns
    for r in rows:
        points.setdefault(tuple(r[k] for k in sweep), len(points))
    # a run's order: by step, then sweep point, then seed (as the trainer writes it)
    rows.sort(key=lambda r: (int(r["step"]), points[tuple(r[k] for k in sweep)],
                             int(r["seed"])))
    with open(os.path.join(out, f"{name}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, header)
        w.writeheader()
        w.writerows(rows)
    gits = {str(recs[p].get("git")) for p in parts}
    record = {"run": name, "flags": recs[parts[0]]["flags"],
              "wall_s": max(recs[p]["wall_s"] for p in parts), "steps_done": cut,
              "device": " / ".join(sorted({recs[p]["device"] for p in parts})),
              "config": {**configs[0], "seed": seeds, "seeds": offset},
              **({"git": recs[parts[0]]["git"]} if len(gits) == 1 else {}),
              "merged": [{"run": p, "seed": c["seed"], "seeds": c["seeds"],
                          "steps_done": recs[p]["steps_done"], "device": recs[p]["device"],
                          "git": recs[p].get("git"), "command": recs[p].get("command")}
                         for p, c in zip(parts, configs, strict=True)]}
    differ = {k: [c.get(k) for c in configs] for k in allow
              if len({repr(c.get(k)) for c in configs}) > 1}
    if differ:
        record["allowed_differences"] = differ
    if dropped:  # metrics some parts' commits did not log yet; each part's CSV keeps its own
        record["columns_dropped"] = dropped
    run_grid.record(out, record)
    return record


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="the run_grid.py --out the parts share")
    p.add_argument("merges", nargs="+", metavar="NAME=PART,PART,...",
                   help="PART: a run recorded in --out, or DIR/RUN for one recorded in DIR")
    p.add_argument("--allow", default="", metavar="FIELD,...",
                   help="config fields the parts may differ in besides the seed")
    args = p.parse_args(argv)
    allow = tuple(f for f in args.allow.split(",") if f)
    for m in args.merges:
        name, _, parts = m.partition("=")
        rec = merge(args.out, name, parts.split(","), allow)
        print(f"{name}: {plural(rec['config']['seeds'], 'seed')} from "
              f"{plural(len(rec['merged']), 'part')}, cut at "
              f"{rec['steps_done']:,} steps", flush=True)


if __name__ == "__main__":
    main()
