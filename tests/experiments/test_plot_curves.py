"""plot_curves: mean and std over seeds, cumulative sums and trailing smoothing per seed."""

import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import plot_curves  # noqa: E402


@pytest.fixture
def csv_path(tmp_path):
    # two seeds, three evaluations; seed 1 has no value at the second (a NaN gap)
    path = tmp_path / "run.csv"
    path.write_text("step,seed,falls\n10,0,1\n10,1,3\n20,0,2\n20,1,nan\n30,0,6\n30,1,5\n")
    return str(path)


def test_mean_std_over_seeds_and_cumulative(csv_path):
    steps, mean, std = plot_curves.curve(csv_path, "falls")
    np.testing.assert_array_equal(steps, [10, 20, 30])
    np.testing.assert_allclose(mean, [2, 2, 5.5])
    np.testing.assert_allclose(std, [1, 0, 0.5])
    _, mean, _ = plot_curves.curve(csv_path, "falls", cumulative=True)
    # seed 1's sum is NaN after its gap, so only seed 0 (1, 3, 9) counts there
    np.testing.assert_allclose(mean, [2, 3, 9])


def test_smoothing_averages_each_seed_over_its_last_evaluations(csv_path, tmp_path):
    _, mean, _ = plot_curves.curve(csv_path, "falls", smooth=2)
    # seed 0: 1, 1.5, 4; seed 1: 3, 3 (its gap skipped), 5
    np.testing.assert_allclose(mean, [2, 2.25, 4.5])
    out = str(tmp_path / "fig.png")
    plot_curves.main([csv_path, "--metric", "falls", "--smooth", "2", "--out", out])
    assert os.path.getsize(out) > 1000
    with pytest.raises(SystemExit):
        plot_curves.main([csv_path, "--smooth", "0", "--out", out])


def test_a_sweep_gives_one_curve_per_value(tmp_path):
    path = tmp_path / "sweep.csv"
    path.write_text("step,seed,flr_alpha,falls\n10,0,0.1,1\n10,1,0.1,3\n10,0,0.001,7\n"
                    "10,1,0.001,9\n")
    # in the run's order
    assert plot_curves.sweep_values(str(path)) == [{"flr_alpha": "0.1"},
                                                   {"flr_alpha": "0.001"}]
    _, mean, _ = plot_curves.curve(str(path), "falls", where={"flr_alpha": "0.1"})
    np.testing.assert_allclose(mean, [2])
    _, mean, _ = plot_curves.curve(str(path), "falls", where={"flr_alpha": "0.001"})
    np.testing.assert_allclose(mean, [8])
    plain = tmp_path / "plain.csv"
    plain.write_text("step,seed,falls\n10,0,1\n")
    assert plot_curves.sweep_values(str(plain)) == [{}]
    out = str(tmp_path / "fig.png")
    plot_curves.main([str(path), str(plain), "--metric", "falls", "--out", out])
    assert os.path.getsize(out) > 1000


def test_where_keeps_sweep_points_and_labels_name_what_differs(tmp_path):
    path = tmp_path / "points.csv"
    path.write_text("step,seed,flr_alpha,flr_eps,flr_next,falls\n"
                    "10,0,0.0,2.0,sample,4\n10,0,0.01,2.0,sample,2\n10,0,0.01,0.5,sample,3\n"
                    "10,0,0.01,2.0,goal,5\n")
    keep = [plot_curves._where("flr_alpha=0,0.01"), plot_curves._where("flr_next=sample")]
    assert [p for p in plot_curves.sweep_values(str(path)) if plot_curves._keep(p, keep)] == [
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
    one curve, silently: every sweep field now has a column, and duplicates are refused."""
    from flrjax import config

    assert set(plot_curves.SWEEP_COLUMNS) == set(config.SWEEP_FIELDS)
    path = tmp_path / "sweep.csv"
    path.write_text("step,seed,pig_jump_temp,success_rate\n10,0,0.0111,0\n10,0,1.0,1\n")
    assert [p["pig_jump_temp"] for p in plot_curves.sweep_values(str(path))] == ["0.0111",
                                                                                "1.0"]
    unknown = tmp_path / "unknown.csv"
    unknown.write_text("step,seed,other,success_rate\n10,0,a,0\n10,0,b,1\n")
    with pytest.raises(ValueError, match="two rows for seed 0 at step 10"):
        plot_curves.curve(str(unknown), "success_rate")


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
