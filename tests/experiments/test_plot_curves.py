"""plot_curves: mean and sample std over seeds, cumulative sums and trailing smoothing per
seed, bands clipped to the metric's range, the paper's names in legends, a common step cut."""

import json
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import plot_curves  # noqa: E402

from flrjax import analysis  # noqa: E402


def test_main_draws_a_sweep_and_a_plain_run_smoothed(tmp_path):
    """One figure from a sweep's CSV and a plain run's; a smoothing window below 1 is refused."""
    path = tmp_path / "sweep.csv"
    path.write_text("step,seed,flr_alpha,falls\n10,0,0.1,1\n10,1,0.1,3\n10,0,0.001,7\n"
                    "10,1,0.001,9\n20,0,0.1,2\n20,1,0.1,2\n20,0,0.001,5\n20,1,0.001,6\n")
    plain = tmp_path / "plain.csv"
    plain.write_text("step,seed,falls\n10,0,1\n20,0,3\n")
    out = str(tmp_path / "fig.png")
    plot_curves.main([str(path), str(plain), "--metric", "falls", "--smooth", "2", "--out", out])
    assert os.path.getsize(out) > 1000
    with pytest.raises(SystemExit):
        plot_curves.main([str(plain), "--smooth", "0", "--out", out])


def test_where_keeps_sweep_points_and_labels_name_what_differs(tmp_path):
    path = tmp_path / "points.csv"
    path.write_text("step,seed,flr_alpha,flr_eps,flr_next,falls\n"
                    "10,0,0.0,2.0,sample,4\n10,0,0.01,2.0,sample,2\n10,0,0.01,0.5,sample,3\n"
                    "10,0,0.01,2.0,goal,5\n")
    keep = [plot_curves._where("flr_alpha=0,0.01"), plot_curves._where("flr_next=sample")]
    assert [p for p in analysis.sweep_values(str(path)) if plot_curves._keep(p, keep)] == [
        {"flr_alpha": "0.0", "flr_eps": "2.0", "flr_next": "sample"},
        {"flr_alpha": "0.01", "flr_eps": "2.0", "flr_next": "sample"},
        {"flr_alpha": "0.01", "flr_eps": "0.5", "flr_next": "sample"}]
    assert plot_curves.point_label({"flr_alpha": "0.0", "flr_eps": "2.0"}) == \
        "α=0.0 (no FLR) ε=2.0"
    assert plot_curves.point_label({"flr_alpha": "0.01"}) == "α=0.01 (FLR)"
    out = str(tmp_path / "fig.png")
    plot_curves.main([str(path), "--metric", "falls", "--where", "flr_next=sample",
                      "--out", out])
    assert os.path.getsize(out) > 1000
    for bad in (["--where", "flr_next=never"], ["--where", "polyak=1"]):
        with pytest.raises(SystemExit):
            plot_curves.main([str(path), "--metric", "falls", *bad, "--out", out])


def test_every_sweepable_field_is_a_curve_and_unknown_sweeps_are_refused(tmp_path):
    """A field the trainer sweeps but the plot did not know once merged two runs' rows into
    one curve, silently: every sweep field (the trainer's own list) is a column, and
    duplicates are refused."""
    path = tmp_path / "sweep.csv"
    path.write_text("step,seed,pig_jump_temp,success_rate\n10,0,0.0111,0\n10,0,1.0,1\n")
    assert [p["pig_jump_temp"] for p in analysis.sweep_values(str(path))] == ["0.0111", "1.0"]
    lr = tmp_path / "lr.csv"
    lr.write_text("step,seed,lr_critic,success_rate\n10,0,0.0003,0\n10,0,0.001,1\n")
    assert len(analysis.sweep_values(str(lr))) == 2
    unknown = tmp_path / "unknown.csv"
    unknown.write_text("step,seed,other,success_rate\n10,0,a,0\n10,0,b,1\n")
    with pytest.raises(ValueError, match="two rows for seed 0 at step 10"):
        analysis.curve(str(unknown), "success_rate")


def test_keep_colors_skips_runs_without_the_metric_but_not_their_colours(tmp_path):
    sweep = tmp_path / "dhrl.csv"
    sweep.write_text("step,seed,flr_alpha,success_rate\n10,0,0,0\n10,0,0.01,1\n")
    pig = tmp_path / "pig.csv"
    pig.write_text("step,seed,success_rate,no_plan_success_rate\n10,0,0,1\n")
    runs, labels = [str(sweep), str(pig)], ["dhrl", "pig"]
    drawn = plot_curves.curves_to_draw(runs, labels, "success_rate", [])
    assert [(label, color) for _, label, _, color in drawn] == [
        ("dhrl α=0 (no FLR)", "C0"), ("dhrl α=0.01 (FLR)", "C1"), ("pig", "C2")]
    # PIG keeps C2 on a plot of a metric only it logs
    kept = plot_curves.curves_to_draw(runs, labels, "no_plan_success_rate", [], keep_colors=True)
    assert [(label, color) for _, label, _, color in kept] == [("pig", "C2")]
    with pytest.raises(ValueError, match="matches --where"):
        plot_curves.curves_to_draw(runs, labels, "success_rate",
                                   [plot_curves._where("flr_alpha=0.5")])


@pytest.mark.parametrize("char", ["i", "W"])
def test_fit_title_wraps_long_titles_inside_the_figure(char):
    """Narrow and wide characters alike: the title is wrapped until it fits the figure."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()
    title = " ".join([char * 8] * 30)
    plot_curves.fit_title(fig, ax, title)
    box = ax.title.get_window_extent()
    assert ax.title.get_text().count("\n") >= 1
    assert 0 <= box.x0 and box.x1 <= fig.bbox.width
    assert ax.title.get_text().replace("\n", " ") == title


def _plot(monkeypatch, argv):
    """Run ``plot_curves.main(argv)`` and return its figure's axes (not written)."""
    from matplotlib.figure import Figure

    figs = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: figs.append(fig))
    plot_curves.main([*argv, "--out", "unused.png"])
    return figs[0].axes[0]


def test_bands_are_clipped_to_the_metrics_range_and_say_which_std(tmp_path, monkeypatch):
    assert analysis.metric_range("success_rate") == (0, 1)
    assert analysis.metric_range("no_plan_success_rate") == (0, 1)
    assert analysis.metric_range("falls") == (0, np.inf)
    assert analysis.metric_range("success_rate", cumulative=True) == (0, np.inf)
    assert analysis.metric_range("reward_gap") == (-np.inf, np.inf)
    path = tmp_path / "run.csv"  # mean 0.1 and std 0.17 at step 10: mean - std < 0
    path.write_text("step,seed,success_rate\n10,0,0\n10,1,0\n10,2,0.3\n"
                    "20,0,1\n20,1,1\n20,2,0.7\n")
    ax = _plot(monkeypatch, [str(path)])
    band = ax.collections[0].get_paths()[0].vertices[:, 1]
    assert band.min() == 0 and band.max() == 1
    assert ax.get_ylabel() == ("success rate at the goal\nmean ± sample std over 3 seeds, "
                               "band clipped to [0, 1]")
    ax = _plot(monkeypatch, [str(path), "--metric", "success_rate", "--cumulative"])
    assert "band clipped to >= 0" in ax.get_ylabel()


def _grid(tmp_path, **runs):
    """CSVs ``NAME.csv`` (rows for 2 seeds at steps 10, 20) and their grid.json records."""
    records = []
    for name, (config, columns, points, last, device) in runs.items():
        lines = [",".join(["step", "seed", *columns, "success_rate"])]
        for step in range(10, last + 1, 10):
            for point in points:
                lines += [",".join([str(step), str(seed), *point, "0.5"]) for seed in (0, 1)]
        (tmp_path / f"{name}.csv").write_text("\n".join(lines) + "\n")
        records.append({"run": name, "config": config, "device": device,
                        "steps_done": last})
    (tmp_path / "grid.json").write_text(json.dumps(records))
    return [str(tmp_path / f"{name}.csv") for name in runs]


def test_legends_name_the_papers_methods_and_only_the_settings_that_differ(tmp_path):
    fig5 = _grid(
        tmp_path,
        dhrl=({"algo": "flr_dhrl", "flr_alpha": [0.0, 0.01], "flr_eps": None, "flr_next": None,
               "initial_episodes": 192}, ["flr_alpha"], [["0.0"], ["0.01"]], 30, "NVIDIA H200"),
        alpha=({"algo": "flr_dhrl", "flr_alpha": [0.001, 0.1], "flr_eps": None,
                "flr_next": None, "initial_episodes": 192}, ["flr_alpha"],
               [["0.001"], ["0.1"]], 20, "NVIDIA H100 80GB HBM3"),
        next=({"algo": "flr_dhrl", "flr_alpha": None, "flr_eps": None, "flr_next": None,
               "initial_episodes": 192}, ["flr_eps", "flr_next"],
              [["0.5", "sample"], ["2.0", "goal"]], 20, "NVIDIA H100 80GB HBM3"))

    def names(runs):
        return [label for _, label, _, _ in plot_curves.curves_to_draw(
            runs, ["x"] * len(runs), "success_rate", [])]

    # alpha 0 is DHRL; alpha shown only where it differs between FLR curves
    assert names(fig5[:2]) == ["DHRL", "FLR+DHRL, α=0.01", "FLR+DHRL, α=0.001",
                               "FLR+DHRL, α=0.1"]
    # eps only where FLR applies and the next subgoal is sampled; an unset alpha is 0.01
    assert names([fig5[0], fig5[2]]) == ["DHRL", "FLR+DHRL, ε=2", "FLR+DHRL, ε=0.5",
                                         "FLR+DHRL, next = final goal"]
    assert names(fig5[:1]) == ["DHRL", "FLR+DHRL"]
    # Fig. 3: the burn-in (a plain flag) from the config; a run directory's config.json
    fig3 = tmp_path / "fig3"
    fig3.mkdir()
    burn_ins = _grid(fig3, **{f"initial_{n}": (
        {"algo": "flr_dhrl", "flr_alpha": [0.0, 0.01], "initial_episodes": n}, ["flr_alpha"],
        [["0.0"], ["0.01"]], 20, "cpu") for n in (192, 48)})
    pig = tmp_path / "pig"
    pig.mkdir()
    (pig / "metrics.csv").write_text("step,seed,success_rate\n10,0,0\n")
    (pig / "config.json").write_text(json.dumps({"config": {"algo": "pig",
                                                            "initial_episodes": 192}}))
    assert names([*burn_ins, str(pig)]) == [
        "DHRL, 192 initial episodes", "FLR+DHRL, 192 initial episodes",
        "DHRL, 48 initial episodes", "FLR+DHRL, 48 initial episodes", "PIG, 192 initial episodes"]
    # no config: the run's label and its sweep values; --legend labels keeps them anyway
    (tmp_path / "grid.json").unlink()
    assert names(fig5[:1]) == ["x α=0.0 (no FLR)", "x α=0.01 (FLR)"]
    assert plot_curves.curves_to_draw(burn_ins[:1], ["mine"], "success_rate", [],
                                      paper=False)[0][1] == "mine α=0.0 (no FLR)"


def test_common_step_cut_devices_and_smoothing_are_stated(tmp_path, monkeypatch):
    runs = _grid(tmp_path,
                 long=({"algo": "higl"}, [], [[]], 40, "NVIDIA H200"),
                 short=({"algo": "pig"}, [], [[]], 20, "NVIDIA H100 80GB HBM3"))
    ax = _plot(monkeypatch, [*runs, "--common-steps", "--smooth", "2", "--title", "fig"])
    assert [line.get_xdata().max() for line in ax.lines] == [20, 20]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["HIGL", "PIG"]
    title = ax.get_title().replace("\n", " ")
    assert title.startswith("fig devices: H100, H200; cut at 20 env steps per seed, the last "
                            "step all curves reach")
    assert title.endswith("smoothed over the last 2 evaluations (20 env steps)")
    ax = _plot(monkeypatch, runs)  # no cut: each curve to its own end
    assert [line.get_xdata().max() for line in ax.lines] == [40, 20]
    assert ax.get_title().replace("\n", " ") == "devices: H100, H200; not smoothed"
    assert analysis.device_name("NVIDIA H100 80GB HBM3") == "H100"
    assert analysis.device_name("cpu") == "CPU"


def test_devices_text_names_every_part_of_a_merged_run(monkeypatch):
    """A run merged from seeds trained on two device kinds names both in the title."""
    devices = {"a": "NVIDIA H100 80GB HBM3 / NVIDIA H200", "b": "NVIDIA H100 80GB HBM3"}
    monkeypatch.setattr(plot_curves, "run_record", lambda run: {"device": devices[run]})
    assert plot_curves.devices_text(["a", "b"]) == "devices: H100, H200"
    assert plot_curves.devices_text(["b"]) == "device: H100"


def test_the_title_states_a_cut_and_a_smoothing_window_only_where_they_apply(tmp_path,
                                                                            monkeypatch):
    """Complete runs of equal length are not "cut"; a window longer than the evaluations a
    curve has is stated as the window it has."""
    runs = _grid(tmp_path, a=({"algo": "higl"}, [], [[]], 20, "cpu"),
                 b=({"algo": "pig"}, [], [[]], 20, "cpu"))
    ax = _plot(monkeypatch, [*runs, "--common-steps", "--smooth", "5"])
    assert ax.get_title().replace("\n", " ") == (
        "device: CPU; smoothed over the last 2 evaluations (20 env steps)")
    ax = _plot(monkeypatch, [runs[0], "--smooth", "2"])
    assert "smoothed over the last 2 evaluations" in ax.get_title()
    assert plot_curves.smoothing_text(5, 10, evaluations=1) == "not smoothed"
    assert plot_curves.smoothing_text(5, 48_000, evaluations=40) == (
        "smoothed over the last 5 evaluations (0.24M env steps)")


def test_curves_and_plots_without_data_are_left_out(tmp_path, monkeypatch, capsys):
    """A metric logged but never measured (NaN in every row, e.g. the reward gap of a point
    mass that never falls) draws no curve; with no curve at all, one line and no file."""
    gap = tmp_path / "gap.csv"
    gap.write_text("step,seed,reward_gap\n10,0,0.5\n10,1,0.7\n20,0,0.6\n20,1,0.8\n")
    empty = tmp_path / "empty.csv"
    empty.write_text("step,seed,reward_gap\n10,0,nan\n10,1,nan\n20,0,\n20,1,nan\n")
    assert analysis.has_data(str(gap), "reward_gap")
    assert not analysis.has_data(str(empty), "reward_gap")
    assert not analysis.has_data(str(gap), "falls")  # no such column
    ax = _plot(monkeypatch, [str(gap), str(empty), "--metric", "reward_gap"])
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["gap"]
    assert len(ax.lines) == 1
    assert ax.get_ylabel().startswith("FLR reward gap: upright − fallen, at a reached subgoal\n")
    out = tmp_path / "none.png"
    with pytest.raises(SystemExit) as e:
        plot_curves.main([str(empty), "--metric", "reward_gap", "--out", str(out)])
    assert e.value.code == 2 and not out.exists()
    assert "no run has a value of reward_gap" in capsys.readouterr().err


def test_axis_labels_name_the_metric_in_words(tmp_path, monkeypatch):
    path = tmp_path / "run.csv"
    path.write_text("step,seed,falls,final_torso_z\n10,0,1,0.5\n20,0,2,0.6\n")
    ax = _plot(monkeypatch, [str(path), "--metric", "falls", "--cumulative"])
    assert ax.get_ylabel() == "cumulative falls per seed\n1 seed"
    assert ax.get_xlabel() == "env steps per seed"
    ax = _plot(monkeypatch, [str(path), "--metric", "final_torso_z"])
    assert ax.get_ylabel().startswith("torso height at the episode's end (m)")
