"""sweep_score.py: each sweep point's time to a success threshold and its success at
wall-clock budgets, on a made-up sweep whose answers are known."""

import csv
import json
import os
import shlex
import sys

import pytest

from flrjax import cli, metrics_io, runner

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import sweep_score  # noqa: E402

FLAGS = ("--env point3leg --seeds 2 --steps 8000 --preset quick --algo flr_dhrl "
         "--lr-critic 1e-3,3e-4 --flr-alpha 0,0.01")
#: Seed-mean success per 1,000 env steps of each point (lr_critic, flr_alpha), capped at 0.9.
RATE = {("0.001", "0.0"): 0.2, ("0.001", "0.01"): 0.4, ("0.0003", "0.0"): 0.1,
        ("0.0003", "0.01"): 0.3}


def _sweep(path) -> str:
    """A finished sweep program's directory: config.json, and metrics.csv in the trainer's
    order (step, point, seed) with made-up numbers: a point's seeds at its seed-mean m(step) =
    min(0.9, rate * step / 1000) -/+ 0.125, the clock at step / 100 s, the landmarks' gap to
    the goal 10 - 10 rate step / 1000 -/+ 1 (no graph yet, NaN, at the first step)."""
    cfg = cli.parse_cli([*shlex.split(FLAGS), "--out", str(path)]).cfg
    os.makedirs(path)
    with open(os.path.join(path, "config.json"), "w") as f:
        json.dump({"config": metrics_io.config_dict(cfg), "device": "GPU"}, f)
    fields = runner.metric_fields(cfg)
    with open(os.path.join(path, "metrics.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fields)
        w.writeheader()
        for step in range(1000, 6000, 1000):
            for (lr, alpha), rate in RATE.items():
                m = min(0.9, rate * step / 1000)
                for seed, off in ((0, -0.125), (1, 0.125)):
                    gap = "nan" if step == 1000 else 10 - 10 * rate * step / 1000 + 8 * off
                    w.writerow({**dict.fromkeys(fields, 0), "step": step, "seed": seed,
                                "lr_critic": lr, "flr_alpha": alpha, "success_rate": m + off,
                                "wall_time": step / 100, "goal_landmark_gap": gap})
    return str(path)


def test_each_point_scored_by_time_to_threshold_and_success_at_budgets(tmp_path, capsys):
    run = _sweep(tmp_path / "sweep")
    out = str(tmp_path / "score" / "lr")
    scores = sweep_score.main([run, "--threshold", "0.75", "--budgets", "5,25,45",
                               "--out", out])
    got = {(s["setting"]["lr_critic"], s["method"]): (s["seconds"], s["env_steps"],
                                                       s["at_budget"]) for s in scores}
    flr = "FLR+DHRL α=0.01"
    assert got == {
        ("0.001", "DHRL"): (40.0, 4000, {"5.0": None, "25.0": pytest.approx(0.4),
                                          "45.0": pytest.approx(0.8)}),
        ("0.001", flr): (20.0, 2000, {"5.0": None, "25.0": pytest.approx(0.8),
                                       "45.0": pytest.approx(0.9)}),
        ("0.0003", "DHRL"): (None, None, {"5.0": None, "25.0": pytest.approx(0.2),
                                           "45.0": pytest.approx(0.4)}),
        ("0.0003", flr): (30.0, 3000, {"5.0": None, "25.0": pytest.approx(0.6),
                                        "45.0": pytest.approx(0.9)}),
    }
    assert all(s["seeds"] == 2 and s["last_step"] == 5000 for s in scores)
    # gap < 5 where rate * step > 500: rate 0.2 from 3,000, 0.4 and 0.3 from 2,000, 0.1 never
    assert {(s["setting"]["lr_critic"], s["method"]): s["landmarks_near_goal"]
            for s in scores} == {("0.001", "DHRL"): 3000, ("0.001", flr): 2000,
                                 ("0.0003", "DHRL"): None, ("0.0003", flr): 2000}
    table = open(out + ".md").read()
    assert table == capsys.readouterr().out
    assert "| landmarks within 5 of the goal (steps) |" in table
    assert table.count("not reached") == 1 and len(table.splitlines()) == 2 + 4
    assert json.load(open(out + ".json"))["points"] == json.loads(json.dumps(scores))
    assert os.path.getsize(out + ".png") > 0


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    run = _sweep(tmp_path / "sweep")
    out = str(tmp_path / "score")
    for argv, message in (([run, "--threshold", "1.5"], "--threshold is a success rate"),
                          ([run, "--budgets", "60,-1"], "budgets must be positive"),
                          ([run, "--gap", "0"], "--gap is a distance > 0"),
                          ([str(tmp_path / "none")], "No such file"),
                          ([str(tmp_path)], "No such file")):
        with pytest.raises(SystemExit):
            sweep_score.main([*argv, "--out", out])
        assert message in capsys.readouterr().err
    assert not os.path.exists(out + ".md")


def test_a_points_method_is_named_by_the_flags_that_make_it_that_method():
    """FLR's α names the method; the settings a base method has too (the high level's subgoal
    noise, a learning rate) are the point's setting, to plot against."""
    point = {"flr_alpha": "0.01", "subgoal_noise_eps": "4.0", "lr_critic": "0.001"}
    assert sweep_score.split_point("flr_dhrl", point) == (
        "FLR+DHRL α=0.01", {"subgoal_noise_eps": "4.0", "lr_critic": "0.001"})
    assert sweep_score.split_point("flr_dhrl", {**point, "flr_alpha": "0.0"})[0] == "DHRL"
    assert sweep_score.split_point("dhrl", {"subgoal_noise_eps": "1.0"}) == (
        "DHRL", {"subgoal_noise_eps": "1.0"})
    assert sweep_score.split_point(None, point) == ("", point)


def test_runs_of_one_name_in_two_folders_are_told_apart_by_their_folder():
    assert sweep_score.run_names(["a/levers/x.csv", "b/levers2/x.csv", "a/levers/y.csv",
                                  "runs/z/"]) == ["levers/x", "levers2/x", "y", "z"]


def test_a_run_cut_short_has_no_success_at_budgets_past_its_last_evaluation():
    rows = [{"step": s, "seed": 0, "success_rate": 0.5, "wall_time": s / 100}
            for s in (1000, 2000)]
    cut = sweep_score.score_point(rows, 0.8, [15, 30], steps_planned=3000)["at_budget"]
    done = sweep_score.score_point(rows, 0.8, [15, 30], steps_planned=2000)["at_budget"]
    assert cut == {"15": 0.5, "30": None} and done == {"15": 0.5, "30": 0.5}


def test_a_list_sweeps_labels_name_what_each_point_changes_from_the_shared_base():
    base = {"polyak": "0.995", "target_noise": "0.0016666666666666668", "lr_critic": "0.001"}
    points = [base, {**base, "polyak": "0.95"}, {**base, "target_noise": "0.05"},
              {**base, "lr_critic": "0.003"}]
    scores = [{"run": "levers", "method": "FLR+DHRL", "setting": p} for p in points]
    assert [sweep_score._setting_text(s, scores) for s in scores] == [
        "levers", "polyak=0.95", "target noise=0.05", "critic lr=0.003"]
    # a product sweep's values are each shared by half the points: every point shows them
    pair = [{"run": "lr", "method": m, "setting": {"lr_critic": v}}
            for m in ("DHRL", "FLR+DHRL") for v in ("0.001", "0.002")]
    assert [sweep_score._setting_text(s, pair) for s in pair] == ["critic lr=0.001",
                                                                  "critic lr=0.002"] * 2


def test_a_run_of_one_alpha_names_its_method_as_a_run_sweeping_alpha_does(tmp_path):
    run = _sweep(tmp_path / "sweep")
    with open(os.path.join(run, "metrics.csv")) as f:
        rows = [r for r in csv.DictReader(f) if r["flr_alpha"] == "0.01"]
    config = json.loads((tmp_path / "sweep" / "config.json").read_text())
    config["config"]["flr_alpha"] = 0.01
    one = tmp_path / "one"
    one.mkdir()
    (one / "config.json").write_text(json.dumps(config))
    with open(one / "metrics.csv", "w", newline="") as f:
        w = csv.DictWriter(f, [k for k in rows[0] if k != "flr_alpha"])
        w.writeheader()
        w.writerows({k: v for k, v in r.items() if k != "flr_alpha"} for r in rows)
    swept = {s["method"] for s in sweep_score.score([run], 0.8, [])}
    assert {s["method"] for s in sweep_score.score([str(one)], 0.8, [])} == \
        swept - {"DHRL"} == {"FLR+DHRL α=0.01"}
