"""flrjax.analysis: mean and sample std over seeds, cumulative sums and trailing smoothing per
seed, sweep points read from a CSV, the paper's names, plurals."""

import numpy as np
import pytest

from flrjax import analysis


@pytest.fixture
def csv_path(tmp_path):
    # two seeds, three evaluations; seed 1 has no value at the second (a NaN gap)
    path = tmp_path / "run.csv"
    path.write_text("step,seed,falls\n10,0,1\n10,1,3\n20,0,2\n20,1,nan\n30,0,6\n30,1,5\n")
    return str(path)


def test_mean_std_over_seeds_and_cumulative(csv_path):
    steps, mean, std = analysis.curve(csv_path, "falls")
    np.testing.assert_array_equal(steps, [10, 20, 30])
    np.testing.assert_allclose(mean, [2, 2, 5.5])
    # the sample std (ddof 1); 0 where one seed has a value
    np.testing.assert_allclose(std, [np.sqrt(2), 0, np.sqrt(0.5)])
    _, mean, _ = analysis.curve(csv_path, "falls", cumulative=True)
    # seed 1's sum is NaN after its gap, so only seed 0 (1, 3, 9) counts there
    np.testing.assert_allclose(mean, [2, 3, 9])


def test_smoothing_averages_each_seed_over_its_last_evaluations(csv_path):
    _, mean, _ = analysis.curve(csv_path, "falls", smooth=2)
    # seed 0: 1, 1.5, 4; seed 1: 3, 3 (its gap skipped), 5
    np.testing.assert_allclose(mean, [2, 2.25, 4.5])


def test_a_sweep_gives_one_curve_per_value(tmp_path):
    path = tmp_path / "sweep.csv"
    path.write_text("step,seed,flr_alpha,falls\n10,0,0.1,1\n10,1,0.1,3\n10,0,0.001,7\n"
                    "10,1,0.001,9\n")
    # in the run's order
    assert analysis.sweep_values(str(path)) == [{"flr_alpha": "0.1"}, {"flr_alpha": "0.001"}]
    _, mean, _ = analysis.curve(str(path), "falls", where={"flr_alpha": "0.1"})
    np.testing.assert_allclose(mean, [2])
    _, mean, _ = analysis.curve(str(path), "falls", where={"flr_alpha": "0.001"})
    np.testing.assert_allclose(mean, [8])
    plain = tmp_path / "plain.csv"
    plain.write_text("step,seed,falls\n10,0,1\n")
    assert analysis.sweep_values(str(plain)) == [{}]
    with pytest.raises(ValueError, match="two rows for seed 0 at step 10"):
        analysis.curve(str(path), "falls")  # both points' rows in one table


def test_sweep_points_are_named_as_the_paper_names_the_methods():
    assert analysis.point_name("flr_dhrl", {}) == "FLR+DHRL"
    assert analysis.point_name("flr_dhrl", {"flr_alpha": 0.0}) == "DHRL"
    assert analysis.point_name("flr_pig", {"flr_alpha": 0.0, "flr_eps": 0.5}) == "PIG"
    assert analysis.point_name("flr_dhrl", {"flr_alpha": 0.01, "flr_next": "goal"}) == \
        "FLR+DHRL α=0.01 next=goal"
    assert analysis.point_name("dhrl", {"initial_episodes": 48}) == "DHRL initial episodes=48"


def test_swept_numbers_show_at_most_four_significant_digits_and_words_as_they_are():
    assert analysis.point_name("flr_dhrl", {"target_noise": 0.05 / 30, "polyak": 0.995}) == \
        "FLR+DHRL target noise=0.001667 polyak=0.995"
    assert [analysis.value_text(v) for v in ("0.0", "0.0016666666666666668", 3e-4, "goal", 48)] \
        == ["0.0", "0.001667", "0.0003", "goal", "48"]


def test_plural_is_singular_for_exactly_one():
    assert analysis.plural(1, "seed") == "1 seed"
    assert analysis.plural(2, "seed") == "2 seeds"
    assert analysis.plural(1.0, "update") == "1 update"
    assert analysis.plural(0.25, "update") == "0.25 updates"
    assert analysis.plural(1200, "chunk") == "1,200 chunks"


def test_sample_std_uses_ddof_1():
    x = [1.0, 2.0, 3.0, 4.0]
    assert analysis.sample_std(x) == pytest.approx(np.sqrt(5 / 3))  # not sqrt(5/4) (ddof 0)
    assert np.isnan(analysis.sample_std([0.5]))
    table = np.array([[1.0, 2.0, 4.0], [3.0, 3.0, 3.0]])
    np.testing.assert_allclose(analysis.sample_std(table), [np.std([1, 2, 4], ddof=1), 0])
    np.testing.assert_allclose(analysis.sample_std(table, axis=0), np.std(table, 0, ddof=1))
    assert np.isnan(analysis.sample_std(np.ones((3, 1)))).all()


def test_a_run_record_is_its_config_json_or_its_grid_json_entry(tmp_path):
    """A run directory's metrics.csv reads its config.json; NAME.csv its grid.json entry."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text('{"device": "cpu", "config": {"steps": 400}}')
    (run / "metrics.csv").write_text("step,seed,falls\n10,0,1\n")
    assert analysis.run_record(str(run))["config"]["steps"] == 400
    assert analysis.run_record(str(run / "metrics.csv"))["device"] == "cpu"
    (tmp_path / "grid.json").write_text('[{"run": "a", "device": "H100"}, {"run": "b"}]')
    assert analysis.run_record(str(tmp_path / "a.csv")) == {"run": "a", "device": "H100"}
    assert analysis.run_record(str(tmp_path / "c.csv")) == {}
    assert analysis.select([{"x": "0.50"}, {"x": "goal"}], [("x", "0.5")]) == [{"x": "0.50"}]


def test_a_metrics_range_is_declared_not_guessed_from_its_name():
    for metric in analysis.UNIT_METRICS:
        assert analysis.metric_range(metric) == (0, 1)
    for metric in analysis.NONNEGATIVE_METRICS:
        assert analysis.metric_range(metric) == (0, np.inf)
    for metric in analysis.CORRELATION_METRICS:
        assert analysis.metric_range(metric) == (-1, 1)
        assert analysis.metric_range(metric, cumulative=True) == (-np.inf, np.inf)
    # a name that merely ends like a rate or a distance is not clipped
    assert analysis.metric_range("new_frac") == (-np.inf, np.inf)
    assert analysis.metric_range("new_distance") == (-np.inf, np.inf)
