"""The figure scripts end to end at a CPU budget: runs, CSVs, plots, a time-limited grid."""

import csv
import json
import os
import shlex
import sys

import numpy as np
import pytest

from flrjax import cli, config, presets, runner

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import figures  # noqa: E402
import plot_curves  # noqa: E402

from flrjax import analysis  # noqa: E402

TINY = ("--preset quick --num-envs 4 --initial-episodes 4 --episodes-per-chunk 1 --hidden 16 "
        "--batch-size 32 --graph-start-steps 0 --max-landmarks 8 --landmark-sample 64")


def _steps(path):
    with open(path) as f:
        return [int(r["step"]) for r in csv.DictReader(f)]


def test_fig5_runs_its_points_continues_after_a_time_limit_and_plots(tmp_path, capsys):
    out, runs = str(tmp_path / "fig"), str(tmp_path / "runs")
    argv = ["fig5", "--env", "point3leg", "--seeds", "2", "--steps", "800", "--extra", TINY,
            "--out", out, "--runs", runs, "--only", "dhrl,flr_dhrl_alpha"]
    # a limit shorter than a chunk (compiling alone takes longer): the first run stops after
    # its first chunk, checkpointed, and the second is not started
    figures.main([*argv, "--time-limit", "3"])
    csv_path = os.path.join(out, "dhrl.csv")
    assert _steps(csv_path) == [400] * 4
    assert not os.path.exists(os.path.join(out, "flr_dhrl_alpha.csv"))
    assert os.listdir(os.path.join(runs, "dhrl", "checkpoints")) == ["chunk_000001"]
    figures.main(argv)  # the same command again resumes it and runs the next
    assert _steps(csv_path) == [400] * 4 + [800] * 4
    # DHRL (alpha 0) and FLR+DHRL, then alphas 0.001 and 0.1, each run in its order
    alpha_path = os.path.join(out, "flr_dhrl_alpha.csv")
    assert [p["flr_alpha"] for p in analysis.sweep_values(csv_path)] == ["0.0", "0.01"]
    assert [p["flr_alpha"] for p in analysis.sweep_values(alpha_path)] == ["0.001", "0.1"]
    grid = json.load(open(os.path.join(out, "grid.json")))
    assert [(r["run"], r["steps_done"]) for r in grid] == [("dhrl", 800),
                                                           ("flr_dhrl_alpha", 800)]
    assert grid[0]["config"]["env"] == "point3leg"
    assert set(grid[0]["git"]) == {"commit", "clean"} and grid[0]["command"]  # provenance
    assert os.path.getsize(os.path.join(out, "fig5_alpha_success_rate.png")) > 1000
    # the point mass cannot fall (no falls plot) and so has no reward gap (no data: no plot);
    # the next-subgoal panel waits for its run (eps 0.5 and the final goal)
    assert sorted(f for f in os.listdir(out) if f.endswith(".png")) == [
        "fig5_alpha_success_rate.png"]
    assert not any(f.startswith(".grid") for f in os.listdir(out))  # no lock file left
    assert figures._title("fig5", "point3leg", out, ["dhrl"], panel="alpha") == (
        "Fig. 5 (α), PointMaze room, 2 seeds\n800 env steps per seed")
    # falls are plotted cumulatively, per seed
    steps, mean, _ = analysis.curve(csv_path, "falls", cumulative=True,
                                       where={"flr_alpha": "0.0"})
    assert list(steps) == [400, 800] and np.all(np.diff(mean) >= 0)
    capsys.readouterr()
    figures.main(argv)  # nothing left to run
    assert capsys.readouterr().out.count("finished before, skipped") == 2


def test_fig5_runs_are_the_paper_points(tmp_path, monkeypatch):
    """Fig. 2's DHRL / FLR+DHRL run, alpha 0.001 and 0.1, eps 0.5 and the final goal: Fig. 5's
    six points, as three runs of two."""
    calls = []
    monkeypatch.setattr(figures.run_grid, "main", calls.append)
    figures.main(["fig5", "--out", str(tmp_path)])
    variants = [a for a in calls[0] if "=--algo" in a]
    assert variants == ["dhrl=--algo flr_dhrl --flr-alpha 0,0.01",
                        "flr_dhrl_alpha=--algo flr_dhrl --flr-alpha 0.001,0.1",
                        "flr_dhrl_next=--algo flr_dhrl --sweep 'flr-eps=0.5; flr-next=goal'"]
    cfg = cli.parse_cli(["--algo", "flr_dhrl", "--sweep", "flr-eps=0.5; flr-next=goal"]).cfg
    assert config.sweep_points(cfg) == [{"flr_eps": 0.5, "flr_next": "sample"},
                                        {"flr_eps": 2.0, "flr_next": "goal"}]
    figures.main(["fig5", "--out", str(tmp_path), "--only", "dhrl", "--adopt", "a,b"])
    assert calls[1][calls[1].index("--adopt") + 1] == "a,b"


def test_fig3_runs_fig2s_dhrl_run_and_two_burn_ins_labelled_by_their_config(tmp_path,
                                                                          monkeypatch):
    """Fig. 3: DHRL / FLR+DHRL after 192 (Fig. 2's run, the default), 96 and 48 initial random
    episodes, as three runs of two points; the legend names each run's burn-in."""
    calls = []
    monkeypatch.setattr(figures.run_grid, "main", calls.append)
    figures.main(["fig3", "--out", str(tmp_path)])
    argv = calls[0]
    base = argv[argv.index("--base") + 1]
    variants = dict(a.split("=", 1) for a in argv if "=--algo" in a)
    assert list(variants) == ["dhrl", "initial_48", "initial_96"]
    for name, episodes in (("dhrl", 192), ("initial_48", 48), ("initial_96", 96)):
        cfg = cli.parse_cli(shlex.split(f"{base} {variants[name]}")).cfg
        assert (cfg.algo, cfg.flr_alpha, cfg.initial_episodes) == (
            "flr_dhrl", (0.0, 0.01), episodes)  # a run's own flag wins over --extra's
    (tmp_path / "grid.json").write_text(json.dumps(
        [{"run": "initial_96", "config": {"initial_episodes": 96}}]))
    assert figures._legend("fig3", str(tmp_path), "initial_96") == "96 initial episodes"
    assert figures._legend("fig3", str(tmp_path), "dhrl") == "dhrl"  # no record yet
    assert figures._legend("fig5", str(tmp_path), "initial_96") == "initial_96"


def test_fig2_runs_pig_against_flr_pig_in_one_run_and_fig4_replots_it(tmp_path, capsys):
    """Fig. 2's PIG is the alpha 0 point of its FLR+PIG run (the same metrics as a plain
    ``--algo pig`` run), and Fig. 4 with Fig. 2's ``--out`` reuses that run."""
    out, runs = str(tmp_path / "fig"), str(tmp_path / "runs")
    argv = ["--only", "pig", "--env", "point4leg", "--seeds", "2", "--steps", "800", "--extra",
            TINY, "--out", out, "--runs", runs]
    figures.main(["fig2", *argv])
    with open(os.path.join(out, "pig.csv")) as f:
        swept = [r for r in csv.DictReader(f) if r["flr_alpha"] == "0.0"]
    cfg = cli.parse_cli(["--resume", os.path.join(runs, "pig")]).cfg
    assert cfg.algo == "flr_pig" and cfg.flr_alpha == (0.0, 0.01)
    plain = runner.train(cfg.replace(algo="pig", out=None),
                         progress=False)
    assert [r["step"] for r in plain] == [int(r["step"]) for r in swept] == [400] * 2 + [800] * 2
    for k in ("final_goal_distance", "q", "critic_loss", "graph_nodes"):
        np.testing.assert_allclose([float(r[k]) for r in swept], [r[k] for r in plain],
                                   rtol=1e-4, atol=1e-5, err_msg=k)
    for metric in ("success_rate", "no_plan_success_rate"):  # PIG's policy alone too
        assert os.path.getsize(os.path.join(out, f"fig2_{metric}.png")) > 1000
    capsys.readouterr()
    figures.main(["fig4", *argv])
    assert capsys.readouterr().out.count("finished before, skipped") == 1
    # Fig. 4's falls, torso height and reward gap (upright - fallen) do not apply to a point
    # mass, which cannot fall: no plot of them
    assert not [f for f in os.listdir(out) if f.startswith("fig4_")]


def test_fig2_on_ant4leg_runs_pig_without_flr_pig(tmp_path, monkeypatch):
    """The paper shows FLR+PIG on the tripod only: Fig. 2 right's ``pig`` is plain PIG."""
    calls = []
    monkeypatch.setattr(figures.run_grid, "main", calls.append)
    figures.main(["fig2", "--env", "ant4leg", "--out", str(tmp_path)])
    variants = [a for a in calls[0] if "=--algo" in a]
    assert variants == ["dhrl=--algo flr_dhrl --flr-alpha 0,0.01", "pig=--algo pig",
                        "higl=--algo higl"]
    figures.main(["fig2", "--out", str(tmp_path)])  # the tripod keeps FLR+PIG
    assert "pig=--algo flr_pig --flr-alpha 0,0.01" in calls[1]


def test_title_names_each_runs_steps_where_they_differ(tmp_path):
    def record(run, done):
        return {"run": run, "steps_done": done, "device": "GPU",
                "config": {"steps": 1_920_000, "seeds": 5}}
    (tmp_path / "grid.json").write_text(json.dumps([record("dhrl", 1_200_000),
                                                    record("pig", 1_920_000)]))
    assert figures._title("fig2", "ant4leg", str(tmp_path), ["dhrl", "pig"]) == (
        "Fig. 2, AntMaze4Leg, 5 seeds\n"
        "dhrl 1.20M, pig 1.92M env steps per seed (time-limited; 1.92M planned)")
    assert figures._title("fig2", "ant4leg", str(tmp_path), ["pig"]) == (
        "Fig. 2, AntMaze4Leg, 5 seeds\n1.92M env steps per seed")
    # cut at a common step, which plot_curves states: only that the runs were time-limited
    assert figures._title("fig2", "ant4leg", str(tmp_path), ["dhrl", "pig"], cut=True) == (
        "Fig. 2, AntMaze4Leg, 5 seeds, time-limited runs (1.92M steps planned)")
    assert figures._title("fig2", "ant4leg", str(tmp_path), ["pig"], cut=True) == (
        "Fig. 2, AntMaze4Leg, 5 seeds")  # complete: nothing to say
    # runs that finished steps of their own are complete, not time-limited
    short = {**record("short", 960_000), "config": {"steps": 960_000, "seeds": 1}}
    (tmp_path / "grid.json").write_text(json.dumps([short, record("pig", 1_920_000)]))
    assert figures._title("fig3", "ant3leg", str(tmp_path), ["short", "pig"]) == (
        "Fig. 3, AntMaze3Leg, 1/5 seeds\nshort 0.96M, pig 1.92M env steps per seed")


def test_plots_are_smoothed_cut_at_a_common_step_and_name_the_papers_methods(tmp_path,
                                                                            monkeypatch):
    """``--plot-only`` from CSVs and grid.json: success smoothed over the default 5
    evaluations, cumulative falls not; every curve cut at the shortest run's last step;
    legends DHRL / FLR+DHRL / HIGL."""
    records = []
    for name, run_config, last in (("dhrl", {"algo": "flr_dhrl", "flr_alpha": [0.0, 0.01]}, 80),
                               ("higl", {"algo": "higl"}, 50)):
        swept = "flr_alpha" in str(run_config)
        lines = ["step,seed," + ("flr_alpha," if swept else "") + "success_rate,falls"]
        for step in range(10, last + 1, 10):
            for alpha in ("0.0", "0.01") if swept else (None,):
                lines += [f"{step},{seed}," + (f"{alpha}," if alpha else "") + "0.5,1"
                          for seed in (0, 1)]
        (tmp_path / f"{name}.csv").write_text("\n".join(lines) + "\n")
        records.append({"run": name, "steps_done": last, "device": "NVIDIA H200",
                        "config": {**run_config, "steps": 80, "seeds": 2}})
    (tmp_path / "grid.json").write_text(json.dumps(records))
    calls = []
    real = plot_curves.main
    monkeypatch.setattr(plot_curves, "main", lambda argv: calls.append(argv) or real(argv))
    figures.main(["fig2", "--out", str(tmp_path), "--plot-only"])
    success = next(a for a in calls if "success_rate" in a)
    assert "--common-steps" in success and success[success.index("--smooth") + 1] == "5"
    assert figures.SMOOTH == 5
    (tmp_path / "fig2_success_rate.png").unlink()
    calls.clear()
    figures.main(["fig4", "--out", str(tmp_path), "--plot-only", "--full-steps"])
    falls = next(a for a in calls if "falls" in a)
    assert "--cumulative" in falls and "--smooth" not in falls
    assert "--common-steps" not in falls
    assert os.path.getsize(tmp_path / "fig4_falls.png") > 1000
    # the drawn plot: its legend, cut and smoothing
    from matplotlib.figure import Figure

    figs = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: figs.append(fig))
    figures.main(["fig2", "--out", str(tmp_path), "--plot-only"])
    ax = figs[0].axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["DHRL", "FLR+DHRL", "HIGL"]
    assert {line.get_xdata().max() for line in ax.lines} == {50}
    title = ax.get_title().replace("\n", " ")
    assert "time-limited runs" in title and "device: H200" in title
    assert "cut at 50 env steps per seed" in title
    assert "smoothed over the last 5 evaluations (50 env steps)" in title


def test_take_copies_another_figures_run_in_before_plotting(tmp_path):
    """``--take DIR/RUN``: the run's CSV and grid.json record come into --out, and the figure
    plots it with the runs already there."""
    other, out = tmp_path / "fig3", tmp_path / "fig2"
    other.mkdir()
    out.mkdir()
    for folder, name in ((other, "dhrl"), (out, "higl")):
        swept = name == "dhrl"
        lines = ["step,seed," + ("flr_alpha," if swept else "") + "success_rate"]
        for step in (10, 20):
            lines += [f"{step},{seed}," + (f"{a}," if swept else "") + "0.5"
                      for a in (("0.0", "0.01") if swept else (None,)) for seed in (0, 1)]
        (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")
        config = {"algo": "flr_dhrl", "flr_alpha": [0.0, 0.01]} if swept else {"algo": "higl"}
        (folder / "grid.json").write_text(json.dumps([{
            "run": name, "steps_done": 20, "device": "cpu",
            "config": {**config, "steps": 20, "seeds": 2}}]))
    figures.main(["fig2", "--out", str(out), "--take", str(other / "dhrl"), "--plot-only"])
    assert (out / "dhrl.csv").read_text() == (other / "dhrl.csv").read_text()
    assert set(json.loads((out / "grid.json").read_text())[i]["run"] for i in (0, 1)) == {
        "dhrl", "higl"}
    assert os.path.getsize(out / "fig2_success_rate.png") > 1000


def _complete_fig5(folder, env: str, evaluations: int) -> None:
    """Fig. 5's three runs, complete (each reached its steps), as CSVs and grid.json records:
    2 seeds, an evaluation every 10 steps; falls 1 per evaluation; no reward gap at all (NaN,
    as a point mass logs it) but in the alpha run."""
    records = []
    for name, column, points in (("dhrl", "flr_alpha", ["0.0", "0.01"]),
                                 ("flr_dhrl_alpha", "flr_alpha", ["0.001", "0.1"]),
                                 ("flr_dhrl_next", "flr_eps,flr_next", ["0.5,sample",
                                                                        "2.0,goal"])):
        lines = [f"step,seed,{column},success_rate,falls,reward_gap"]
        for step in range(10, 10 * evaluations + 1, 10):
            gap = "0.2" if name == "flr_dhrl_alpha" else "nan"
            lines += [f"{step},{seed},{p},0.5,1,{gap}" for p in points for seed in (0, 1)]
        (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")
        records.append({"run": name, "steps_done": 10 * evaluations, "device": "cpu",
                        "config": {"algo": "flr_dhrl", "env": env, "seeds": 2,
                                   "steps": 10 * evaluations, "flr_eps": None,
                                   "flr_next": None}})
    (folder / "grid.json").write_text(json.dumps(records))


def test_figure_plots_are_titled_truly_and_leave_out_what_does_not_apply(tmp_path,
                                                                        monkeypatch):
    """Complete runs: no "cut", no "time-limited"; a smoothing window no longer than the
    evaluations there are; the point mass has no falls plot; a plot of curves without data is
    not drawn, and a curve without data has no legend entry; axes in words."""
    from matplotlib.figure import Figure

    figs = {}
    monkeypatch.setattr(Figure, "savefig", lambda fig, path, **k: figs.setdefault(
        os.path.basename(path), fig))
    point = tmp_path / "point"
    point.mkdir()
    _complete_fig5(point, "point3leg", evaluations=2)
    figures.main(["fig5", "--env", "point3leg", "--out", str(point), "--plot-only"])
    assert sorted(figs) == ["fig5_alpha_reward_gap.png", "fig5_alpha_success_rate.png",
                            "fig5_next_success_rate.png"]
    ax = figs["fig5_next_success_rate.png"].axes[0]
    assert ax.get_title().replace("\n", " ") == (
        "Fig. 5 (the next subgoal), PointMaze room, 2 seeds device: CPU; smoothed over the "
        "last 2 evaluations (20 env steps)")
    assert ax.get_ylabel().startswith("success rate at the goal\n")
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "DHRL", "FLR+DHRL, ε=2", "FLR+DHRL, ε=0.5", "FLR+DHRL, next = final goal"]
    gap = figs["fig5_alpha_reward_gap.png"].axes[0]  # DHRL's and alpha 0.01's gap is NaN here
    assert [t.get_text() for t in gap.get_legend().get_texts()] == [
        "FLR+DHRL, α=0.001", "FLR+DHRL, α=0.1"]
    figs.clear()
    ant = tmp_path / "ant"
    ant.mkdir()
    _complete_fig5(ant, "ant3leg", evaluations=8)
    figures.main(["fig5", "--env", "ant3leg", "--out", str(ant), "--plot-only"])
    assert "fig5_alpha_falls.png" in figs and "fig5_next_falls.png" in figs
    ax = figs["fig5_alpha_falls.png"].axes[0]
    assert ax.get_title().replace("\n", " ") == (
        "Fig. 5 (α), AntMaze3Leg, 2 seeds device: CPU; not smoothed")
    assert ax.get_ylabel().startswith("cumulative falls per seed\n")
    assert "smoothed over the last 5 evaluations (50 env steps)" in \
        figs["fig5_alpha_success_rate.png"].axes[0].get_title().replace("\n", " ")


def test_a_figure_places_its_runs_as_asked_and_plots_the_others_when_one_fails(tmp_path,
                                                                             monkeypatch):
    """The placement flags go to run_grid.py as they are; a run that failed there (run_grid
    ran the others) leaves the figure plotting what there is, then failing."""
    import launch

    _complete_fig5(tmp_path, "ant3leg", evaluations=2)
    calls = []

    def failing(argv):
        calls.append(argv)
        raise launch.Failed("run_grid: 1 of 3 programs failed: flr_dhrl_next (their logs above)")

    monkeypatch.setattr(figures.run_grid, "main", failing)
    with pytest.raises(launch.Failed, match="flr_dhrl_next"):
        figures.main(["fig5", "--out", str(tmp_path), "--gpus", "0,1", "--submitit", "slurm",
                      "--slurm-partition", "gpu", "--slurm-param", "account=proj"])
    argv = calls[0]
    assert argv[argv.index("--gpus") + 1] == "0,1"
    assert argv[argv.index("--submitit") + 1] == "slurm"
    assert argv[argv.index("--slurm-partition") + 1] == "gpu"
    assert argv[argv.index("--slurm-param") + 1] == "account=proj"
    assert os.path.getsize(tmp_path / "fig5_alpha_success_rate.png") > 1000


def test_the_figures_keep_the_fast_protocol_under_the_gpu_default(monkeypatch):
    """A figure's runs on a GPU train the ``fast`` preset's config, not the default ``tuned``."""
    import jax

    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    argv = shlex.split(f"--env ant3leg --seeds 5 --steps 1920000 {figures.EXTRA} --out /tmp/x")
    got = cli.parse_cli(argv)
    assert got.preset == "fast" and got.cfg == config.TrainConfig(
        env="ant3leg", seeds=5, out="/tmp/x", **presets.PRESETS["fast"])
