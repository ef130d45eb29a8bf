"""run_grid's adoption of finished standalone runs as a variant's sweep points, and a grid run
as jobs of submitit's local executor."""

import csv
import json
import os
import shlex
import sys

import pytest

# imported as the tests are collected, not first within a test: importing submitit configures
# logging (logging.config.dictConfig), which closes the handlers there are, among them absl's,
# whose stream inside a test would be a capture of pytest's that later tests still use
import submitit  # noqa: F401

from flrjax import cli, metrics_io, runner

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import run_grid  # noqa: E402

BASE = "--env point3leg --seeds 2 --steps 8000 --preset quick"
FLAGS = "--algo flr_dhrl --flr-alpha 0,0.01"


def _standalone(path, steps, **changes):
    """A finished standalone run's directory (config.json, metrics.csv) with ``steps``
    evaluations: what ``python -m flrjax.train --out path`` leaves; the metrics are made up
    (``success_rate`` = step / 1000 + seed / 10), adoption only moves them."""
    cfg = cli.parse_cli([*shlex.split(BASE), "--out", str(path)]).cfg
    cfg = cfg.replace(**changes)
    os.makedirs(path)
    with open(os.path.join(path, "config.json"), "w") as f:
        json.dump({"config": metrics_io.config_dict(cfg), "device": "GPU"}, f)
    with open(os.path.join(path, "metrics.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, runner.metric_fields(cfg))
        w.writeheader()
        w.writerows({**dict.fromkeys(runner.metric_fields(cfg), 0), "step": s, "seed": seed,
                     "success_rate": s / 1000 + seed / 10, "wall_time": s / 100}
                    for s in steps for seed in range(2))
    return str(path)


def _cfg():
    cfg = cli.parse_cli([*shlex.split(BASE), *shlex.split(FLAGS)]).cfg
    return cfg


def test_adopt_takes_a_base_run_as_the_alpha_0_point_and_cuts_at_the_common_step(tmp_path):
    flr = _standalone(tmp_path / "flr", [400, 800], algo="flr_dhrl")
    base = _standalone(tmp_path / "base", [400, 800, 1200], algo="dhrl")
    rows, sources = run_grid.adopt(_cfg(), [flr, base])  # any order
    # the order of a vmapped run's CSV: by step, then sweep point, then seed
    assert [(r["step"], r["flr_alpha"], r["seed"]) for r in rows] == [
        (s, a, seed) for s in ("400", "800") for a in (0.0, 0.01) for seed in ("0", "1")]
    assert [float(r["success_rate"]) for r in rows[:4]] == [0.4, 0.5, 0.4, 0.5]
    assert list(rows[0]) == list(runner.metric_fields(_cfg()))
    assert [(s["dir"], s["point"], s["steps_reached"]) for s in sources] == [
        (base, {"flr_alpha": 0.0}, 1200), (flr, {"flr_alpha": 0.01}, 800)]


@pytest.mark.parametrize("changes, message", [
    (dict(algo="flr_dhrl", hidden=32), "differs in hidden"),
    (dict(algo="flr_dhrl", flr_alpha=0.1), "differs in flr_alpha"),
    (dict(algo="pig"), "differs in algo"),
])
def test_adopt_refuses_a_run_that_is_no_sweep_point(tmp_path, changes, message):
    base = _standalone(tmp_path / "base", [400], algo="dhrl")
    other = _standalone(tmp_path / "other", [400], **changes)
    with pytest.raises(SystemExit, match=message):
        run_grid.adopt(_cfg(), [base, other])


def test_adopt_refuses_missing_points_repeats_and_configs_that_predate_a_field(tmp_path):
    base = _standalone(tmp_path / "base", [400], algo="dhrl")
    with pytest.raises(SystemExit, match="2 sweep points, 1 run to adopt"):
        run_grid.adopt(_cfg(), [base])
    again = _standalone(tmp_path / "again", [400], algo="flr_dhrl", flr_alpha=0.0)
    with pytest.raises(SystemExit, match="the same sweep point"):
        run_grid.adopt(_cfg(), [base, again])
    old = _standalone(tmp_path / "old", [400], algo="flr_dhrl")
    path = os.path.join(old, "config.json")
    saved = json.load(open(path))
    del saved["config"]["flr_candidates"]  # a field that applies to FLR+DHRL
    json.dump(saved, open(path, "w"))
    with pytest.raises(SystemExit, match="predates flr_candidates"):
        run_grid.adopt(_cfg(), [base, old])
    with open(os.path.join(base, "config.json")) as f:  # a DHRL run has no FLR or PIG flag
        assert not {"flr_candidates", "pig_jump_temp"} & set(json.load(f)["config"])
    flr = _standalone(tmp_path / "flr", [400], algo="flr_dhrl")
    assert len(run_grid.adopt(_cfg(), [base, flr])[0]) == 4


def test_an_adopted_variant_is_recorded_and_then_skipped(tmp_path, capsys):
    out = str(tmp_path / "out")
    flr = _standalone(tmp_path / "flr", [400, 800], algo="flr_dhrl")
    base = _standalone(tmp_path / "base", [400], algo="dhrl")
    argv = ["--out", out, "--base", BASE, f"dhrl={FLAGS}"]
    run_grid.main([*argv, "--adopt", f"{base},{flr}"])
    with open(os.path.join(out, "dhrl.csv")) as f:
        assert [int(r["step"]) for r in csv.DictReader(f)] == [400] * 4
    record = run_grid.records(out)["dhrl"]
    assert record["steps_done"] == 400 and record["device"] == "GPU"
    assert [s["dir"] for s in record["adopted"]] == [base, flr]
    capsys.readouterr()
    run_grid.main(argv)  # not trained over: it would replace the adopted rows
    assert "dhrl: adopted from" in capsys.readouterr().out


def _record_many(out: str, who: int, n: int) -> None:
    for i in range(n):
        run_grid.record(out, {"run": f"p{who}_{i}", "wall_s": 0.0})


def test_processes_recording_into_one_grid_keep_each_others_records(tmp_path):
    """Several processes (one per GPU) sharing an --out: every record survives, and neither
    a lock file nor a temporary file is left behind."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")  # no forked copy of JAX's threads
    procs = [ctx.Process(target=_record_many, args=(str(tmp_path), w, 25)) for w in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
    assert all(p.exitcode == 0 for p in procs)
    assert sorted(run_grid.records(str(tmp_path))) == sorted(
        f"p{w}_{i}" for w in range(4) for i in range(25))
    assert os.listdir(tmp_path) == ["grid.json"]


def test_a_grid_through_submitits_local_executor_runs_each_variant_once(tmp_path, capsys,
                                                                        monkeypatch):
    """Two tiny variants as jobs of submitit's local executor, side by side on two (fake) GPUs:
    each job trains its variant and records it; the same command again submits nothing. This
    process starts JAX without preallocating before it parses a config."""
    calls = []
    start = run_grid.launch.start_jax_without_preallocating
    monkeypatch.setattr(run_grid.launch, "start_jax_without_preallocating",
                        lambda: (calls.append("start"), start()))
    monkeypatch.setattr(run_grid, "parse_cli",
                        lambda argv: (calls.append("parse"), cli.parse_cli(argv))[1])
    out, runs = str(tmp_path / "out"), str(tmp_path / "runs")
    base = ("--env point3leg --algo flat --seeds 1 --steps 400 --preset quick --num-envs 4 "
            "--initial-episodes 4 --episodes-per-chunk 1 --hidden 16 --batch-size 32")
    argv = ["--out", out, "--runs", runs, "--base", base, "--submitit", "local",
            "--gpus", "0,1", "a=", "b=--seed 1"]
    run_grid.main(argv)
    printed = capsys.readouterr().out
    for name in ("a", "b"):
        assert f": {name}: 400 of 400 steps" in printed  # its summary, from its job
    grid = run_grid.records(out)
    assert {n: (r["steps_done"], r["config"]["seed"]) for n, r in grid.items()} == {
        "a": (400, 0), "b": (400, 1)}
    assert [int(r["step"]) for r in csv.DictReader(open(os.path.join(out, "b.csv")))] == [400]
    jobs = sorted(os.listdir(os.path.join(runs, "submitit")))
    assert len(jobs) == 2 + 1  # the jobs' folders and submitit's own
    assert calls == ["start", "parse", "parse"]
    run_grid.main(argv)
    assert capsys.readouterr().out.count("finished before, skipped") == 2
    assert sorted(os.listdir(os.path.join(runs, "submitit"))) == jobs
