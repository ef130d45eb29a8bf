import dataclasses
import json
import os
import sys
import warnings

import jax
import numpy as np
import pytest

from flrjax import cli, config, metrics_io
from flrjax.algos import flr
from tests.tiny import TINY

#: metrics.csv columns where they are not under test
HEADER = ("step", "seed", "success_rate")


def _rows(success: np.ndarray, points: list[dict]) -> list[dict]:
    """Trainer-shaped rows from success ``[evaluations, points, seeds]``."""
    evals, n, seeds = success.shape
    return [{"step": 100 * (e + 1), "seed": s, **points[p], "success_rate": success[e, p, s],
             "falls": float(e + s), "critic_loss": 1.0 / (e + 1), "wall_time": 10.0 * (e + 1)}
            for e in range(evals) for p in range(n) for s in range(seeds)]


def test_summary_takes_the_last_and_best_evaluation_with_the_sample_std(tmp_path):
    points = [{"flr_alpha": 0.0}, {"flr_alpha": 0.01}]
    success = np.array([[[0.0, 0.0, 0.2], [0.4, 0.6, 0.8]],
                        [[0.1, 0.3, 0.2], [1.0, 1.0, 0.7]],
                        [[0.0, 0.2, 0.4], [0.5, 0.6, 0.7]]])
    (tmp_path / "metrics.csv").write_text("")
    s = metrics_io.summarize("flr_dhrl", points, 3, 1000, _rows(success, points),
                             str(tmp_path))
    dhrl, flr = s["points"]
    assert (dhrl["name"], flr["name"]) == ("DHRL", "FLR+DHRL α=0.01")
    assert dhrl["success"]["mean"] == pytest.approx(0.2)
    assert dhrl["success"]["std"] == pytest.approx(np.std([0.0, 0.2, 0.4], ddof=1))
    assert flr["best_success"] == {"mean": pytest.approx(0.9), "step": 200}
    assert flr["falls_last_eval"] == pytest.approx(3.0)  # falls e + s at e = 2, seeds 0-2
    assert flr["falls_total"] == pytest.approx(np.mean([3, 6, 9]))
    assert (s["env_steps_per_seed"], s["of"], s["wall_time_s"]) == (300, 1000, 30.0)
    assert s["files"] == {"metrics.csv": str(tmp_path / "metrics.csv")}
    text = metrics_io.format_summary(s)
    assert "DHRL: success 0.20 ± 0.20 (best 0.20 at 200)" in text
    assert "sample std" in text and str(tmp_path / "metrics.csv") in text


def test_one_seed_has_no_spread_to_report(tmp_path):
    """With one seed: the value alone, no std in summary.json and no ± in the printed lines."""
    success = np.array([[[0.0]], [[1.0]]])
    s = metrics_io.summarize("flat", [{}], 1, 200, _rows(success, [{}]), None)
    assert s["points"][0]["success"] == {"mean": 1.0} and "std" not in s and "files" not in s
    text = metrics_io.format_summary(s)
    assert "±" not in text and "std" not in text
    assert text.splitlines()[:2] == [
        "200 of 200 env steps per seed, 1 seed, 0.3 min",  # wall time 20 s
        "  flat TD3+HER: success 1.00 (best 1.00 at 200); falls 1.0 in the last evaluation, "
        "1 in all"]


def test_summary_lists_only_the_files_the_run_wrote(tmp_path):
    """A user's notes beside a run are not the run's files."""
    for name in ("config.json", "metrics.csv", "curves.png", "events.out.tfevents.1.host",
                 "notes.txt", "metrics.csv.bak"):
        (tmp_path / name).write_text("")
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "plots").mkdir()
    s = metrics_io.summarize("flat", [{}], 1, 200, _rows(np.zeros((1, 1, 1)), [{}]),
                             str(tmp_path))
    assert list(s["files"]) == ["checkpoints", "config.json", "curves.png",
                                "events.out.tfevents.1.host", "metrics.csv"]
    assert s["files"]["metrics.csv"] == str(tmp_path / "metrics.csv")


def _curves(monkeypatch, env, seeds, steps=None, rows=None, points=({},), algo="flat"):
    """``plot_curves``'s figure (not written) for made-up rows of 2 evaluations."""
    from matplotlib.figure import Figure

    figs = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: figs.append(fig))
    points = list(points)
    if rows is None:
        rows = _rows(np.full((2, len(points), seeds), 0.5), points)
    metrics_io.plot_curves(algo, points, seeds, rows, "unused.png", env, steps)
    return figs[0]


def test_curves_png_names_env_method_and_axes_in_words(monkeypatch):
    fig = _curves(monkeypatch, "ant3leg", 2, steps=200)
    assert [ax.get_ylabel() for ax in fig.axes] == [
        "success rate at the goal",
        "cumulative falls per seed",
        "low-level critic loss"]
    assert {ax.get_xlabel() for ax in fig.axes} == {"env steps per seed"}
    title = fig._suptitle.get_text()
    assert title == "flat TD3+HER on AntMaze3Leg, 2 seeds; mean ± sample std over seeds"
    assert all(ax.collections for ax in fig.axes)  # a ± band on each panel
    # a sweep names its points in the legend; the title says where a short run stopped
    points = [{"flr_alpha": 0.0}, {"flr_alpha": 0.01}]
    fig = _curves(monkeypatch, "ant4leg", 2, steps=1000, points=points, algo="flr_dhrl")
    assert fig._suptitle.get_text() == ("AntMaze4Leg, 2 seeds; mean ± sample std over seeds; "
                                        "stopped at 200 of 1,000 env steps per seed")
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == [
        "DHRL", "FLR+DHRL α=0.01"]


def test_curves_png_leaves_out_falls_for_the_point_mass_and_panels_without_data(monkeypatch):
    """The point mass cannot fall: no falls panel. A metric never measured (NaN in every row)
    is no panel either. One seed: no band, and the title says one seed."""
    rows = [{**r, "critic_loss": np.nan} for r in _rows(np.full((2, 1, 1), 0.5), [{}])]
    fig = _curves(monkeypatch, "point3leg", 1, steps=200, rows=rows)
    assert [ax.get_ylabel() for ax in fig.axes] == ["success rate at the goal"]
    assert fig._suptitle.get_text() == "flat TD3+HER on PointMaze room, 1 seed"
    assert not fig.axes[0].collections  # no band for one seed
    fig = _curves(monkeypatch, "point4leg", 2)
    assert len(fig.axes) == 2 and "U-maze" in fig._suptitle.get_text()


def test_the_command_is_recorded_as_typed(monkeypatch):
    """Under ``python -m flrjax.train``, ``sys.argv[0]`` is the module's absolute path: the
    command is written back as the user typed it; a script keeps its path as given."""
    import types

    main = types.ModuleType("__main__")
    main.__spec__ = types.SimpleNamespace(name="flrjax.train")
    monkeypatch.setitem(sys.modules, "__main__", main)
    argv = ["/home/me/flrjax/flrjax/train.py", "--env", "ant3leg", "--out", "runs/a b"]
    assert metrics_io.command_line(argv) == \
        "python -m flrjax.train --env ant3leg --out 'runs/a b'"
    main.__spec__ = None
    assert metrics_io.command_line(["experiments/figures.py", "fig2"]) == \
        "python experiments/figures.py fig2"


def test_git_state_names_this_checkout_or_nothing(monkeypatch):
    monkeypatch.delenv("FLRJAX_GIT_COMMIT", raising=False)
    state = metrics_io.git_state()
    assert set(state) == {"commit", "clean"}
    if os.path.isdir(os.path.join(os.path.dirname(metrics_io.__file__), "..", ".git")):
        assert len(state["commit"]) == 40 and isinstance(state["clean"], bool)
    monkeypatch.setenv("FLRJAX_GIT_COMMIT", "e7188c7")  # a synced tree says what it is
    monkeypatch.delenv("FLRJAX_GIT_CLEAN", raising=False)
    assert metrics_io.git_state() == {"commit": "e7188c7", "clean": None}
    for value, clean in (("1", True), ("0", False), ("yes", None)):  # and whether it was clean
        monkeypatch.setenv("FLRJAX_GIT_CLEAN", value)
        assert metrics_io.git_state() == {"commit": "e7188c7", "clean": clean}


def test_out_dir_holding_another_run_is_refused(tmp_path):
    metrics_io.prepare_out(dataclasses.replace(TINY, out=str(tmp_path)), HEADER)
    with pytest.raises(config.ConfigError, match="already holds a run with a different config"):
        metrics_io.prepare_out(dataclasses.replace(TINY, out=str(tmp_path), seeds=3), HEADER)


def test_flr_value_chunk_saved_only_when_set_and_old_configs_resume(tmp_path):
    """Unset, it is not in config.json (old runs' configs compare equal); a config.json
    without it resumes with None; a set value is saved and resumed."""
    cfg = TINY.replace(algo="flr_dhrl")
    assert "flr_value_chunk" not in metrics_io.config_dict(cfg)
    assert metrics_io.config_dict(
        cfg.replace(flr_value_chunk=0))["flr_value_chunk"] == 0
    for chunk in (None, 0, 64):
        out = str(tmp_path / f"run{chunk}")
        metrics_io.prepare_out(cfg.replace(out=out, flr_value_chunk=chunk), HEADER)
        resumed, resume = cli.parse_cli(["--resume", out])[:2]
        assert resume and resumed.flr_value_chunk == chunk
        assert flr.from_run(resumed).value_chunk == (128 if chunk is None else chunk or None)
    with pytest.raises(SystemExit):  # a resumed run keeps its own chunk
        cli.parse_cli(["--resume", str(tmp_path / "runNone"), "--flr-value-chunk", "0"])


def test_config_json_names_the_settings_the_defaults_resolved_to(tmp_path, monkeypatch):
    """The device decides several defaults (the flags leave them None): config.json says what
    the run computed with. On a CPU everything float32 and XLA's; on one GPU bf16 FLR values,
    subgoal testing and, for DHRL and FLR+DHRL only, bf16 updates, in the fused kernel."""
    def resolved(algo):
        return metrics_io.resolved_settings(cli.parse_args(
            ["--env", "point3leg", "--algo", algo, "--out", str(tmp_path / algo)]))

    assert resolved("flr_dhrl") == {
        "train_precision": "float32", "flr_precision": "float32", "flr_value_chunk": 128,
        "flr_value_kernel": "xla", "subgoal_test_precision": "float32",
        "subgoal_test_kernel": "xla"}
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert resolved("flr_dhrl") == {
        "train_precision": "bfloat16", "flr_precision": "bfloat16", "flr_value_chunk": None,
        "flr_value_kernel": "fused", "subgoal_test_precision": "bfloat16",
        "subgoal_test_kernel": "fused"}
    assert resolved("dhrl")["train_precision"] == "bfloat16"
    assert resolved("flr_pig") == {"train_precision": "float32", "flr_precision": "bfloat16",
                                   "flr_value_chunk": None, "flr_value_kernel": "fused"}
    assert resolved("higl") == resolved("flat") == {"train_precision": "float32"}
    # a run started on a (faked) GPU and resumed on this CPU says which defaults changed
    gpu_run = dataclasses.replace(TINY, algo="dhrl", out=str(tmp_path / "gpu_run"))
    metrics_io.prepare_out(gpu_run, HEADER)
    monkeypatch.undo()
    with pytest.warns(UserWarning, match="subgoal_test_kernel fused -> xla; subgoal_test_"
                                         "precision bfloat16 -> float32; train_precision "
                                         "bfloat16 -> float32"):
        assert cli.parse_cli(["--resume", gpu_run.out])[1]
    metrics_io.prepare_out(dataclasses.replace(TINY, out=str(tmp_path / "run")), HEADER)
    with open(tmp_path / "run" / "config.json") as f:
        assert json.load(f)["resolved"] == metrics_io.resolved_settings(TINY)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the same device: no warning
        assert cli.parse_cli(["--resume", str(tmp_path / "run")])[1]
