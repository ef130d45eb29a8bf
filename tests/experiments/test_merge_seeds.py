"""merge_seeds: one run's seeds from several processes' run_grid variants, joined."""

import csv
import dataclasses
import os
import shlex
import sys

import pytest

from flrjax import cli, metrics_io, runner

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import merge_seeds  # noqa: E402
import run_grid  # noqa: E402

FLAGS = "--env point3leg --seeds 2 --steps 8000 --preset quick --algo flr_dhrl --flr-alpha 0,0.01"


def _part(out, name, seed, steps, extra=""):
    """A variant of ``out`` as run_grid.py records it: flags with ``--seed seed``, a CSV with
    an evaluation at each of ``steps`` (made-up ``success_rate`` = seed index / 10 + α)."""
    flags = f"{FLAGS} --seed {seed} {extra}".strip()
    cfg = cli.parse_cli(shlex.split(flags)).cfg
    fields = runner.metric_fields(cfg)
    with open(os.path.join(out, f"{name}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fields)
        w.writeheader()
        w.writerows({**dict.fromkeys(fields, 0), "step": s, "seed": i, "flr_alpha": a,
                     "success_rate": i / 10 + a, "wall_time": s / 100}
                    for s in steps for a in (0.0, 0.01) for i in range(cfg.seeds))
    run_grid.record(out, {"run": name, "flags": flags, "wall_s": steps[-1] / 100,
                          "steps_done": steps[-1], "device": "GPU",
                          "config": metrics_io.config_dict(dataclasses.replace(cfg, out=None)),
                          "git": {"commit": "abc", "clean": True}})


def _rows(out, name):
    with open(os.path.join(out, f"{name}.csv")) as f:
        return list(csv.DictReader(f))


def test_seeds_are_renumbered_in_order_cut_at_the_common_step_and_recorded(tmp_path):
    out = str(tmp_path)
    _part(out, "a", 7, [1000, 2000, 3000])
    _part(out, "b", 9, [1000, 2000])
    rec = merge_seeds.merge(out, "pair", ["a", "b"])
    rows = _rows(out, "pair")
    assert {int(r["step"]) for r in rows} == {1000, 2000}
    # 2 steps x 2 points x 4 seeds, each point's seeds 0-1 from a and 2-3 from b
    assert len(rows) == 16
    got = {(r["step"], r["flr_alpha"], r["seed"]): float(r["success_rate"]) for r in rows}
    for a in ("0.0", "0.01"):
        assert [got["2000", a, str(s)] for s in range(4)] == pytest.approx(
            [i / 10 + float(a) for i in (0, 1, 0, 1)])
    assert [(r["step"], r["flr_alpha"]) for r in rows[:5]] == [("1000", "0.0")] * 4 + [
        ("1000", "0.01")]
    assert rec["config"]["seeds"] == 4 and rec["config"]["seed"] == [7, 9]
    assert [(m["run"], m["seed"], m["steps_done"]) for m in rec["merged"]] == [
        ("a", 7, 3000), ("b", 9, 2000)]
    assert run_grid.records(out)["pair"]["steps_done"] == 2000
    assert set(run_grid.records(out)) == {"a", "b", "pair"}


def test_parts_of_other_configs_or_the_same_seed_are_refused(tmp_path):
    out = str(tmp_path)
    _part(out, "a", 7, [1000])
    _part(out, "b", 7, [1000])
    _part(out, "c", 8, [1000], extra="--flr-eps 3")
    with pytest.raises(SystemExit, match="share a seed"):
        merge_seeds.merge(out, "m", ["a", "b"])
    with pytest.raises(SystemExit, match="differs from a in flr_eps"):
        merge_seeds.merge(out, "m", ["a", "c"])
    with pytest.raises(SystemExit, match="no record of z"):
        merge_seeds.merge(out, "m", ["a", "z"])


def test_allowed_fields_may_differ_and_are_recorded(tmp_path):
    """--allow lets the parts differ in the named fields; the record lists each part's value.
    A column one part lacks (a metric its commit did not log) is left out and recorded."""
    out = str(tmp_path)
    _part(out, "a", 7, [1000])
    _part(out, "c", 8, [1000], extra="--flr-eps 3")
    rows = _rows(out, "a")
    with open(os.path.join(out, "a.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, [k for k in rows[0] if k != "falls"])
        w.writeheader()
        w.writerows({k: v for k, v in r.items() if k != "falls"} for r in rows)
    rec = merge_seeds.merge(out, "m", ["a", "c"], allow=("flr_eps",))
    assert rec["columns_dropped"] == ["falls"] and "falls" not in _rows(out, "m")[0]
    assert len(_rows(out, "m")) == 2 * len(rows)
    eps_a = run_grid.records(out)["a"]["config"]["flr_eps"]
    assert rec["allowed_differences"] == {"flr_eps": [eps_a, 3.0]}
    assert eps_a != 3.0 and rec["config"]["seeds"] == 4  # two parts of --seeds 2


def test_parts_from_other_directories_are_copied_in_and_merged(tmp_path):
    """A part named DIR/RUN brings its CSV and record into --out, then merges as a local one;
    a different run of the same name already in --out is refused."""
    out, day2 = str(tmp_path / "out"), str(tmp_path / "day2")
    os.makedirs(out)
    os.makedirs(day2)
    _part(out, "a", 7, [1000, 2000])
    _part(day2, "b", 9, [1000, 2000])
    rec = merge_seeds.merge(out, "pair", ["a", os.path.join(day2, "b")])
    assert [m["run"] for m in rec["merged"]] == ["a", "b"]
    assert _rows(out, "b") == _rows(day2, "b")
    assert run_grid.records(out)["b"] == run_grid.records(day2)["b"]
    assert len(_rows(out, "pair")) == 2 * 2 * 4
    _part(day2, "a", 8, [1000])  # another run named a
    with pytest.raises(SystemExit, match="already records another a"):
        merge_seeds.merge(out, "m", [os.path.join(day2, "a"), "b"])
    with pytest.raises(SystemExit, match="no record of z"):
        merge_seeds.merge(out, "m", ["a", os.path.join(day2, "z")])
