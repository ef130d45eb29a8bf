import csv
import dataclasses
import json
import os
import shlex

import jax
import numpy as np
import pytest
from matplotlib.collections import LineCollection

from flrjax import algos, cli, episodes, runner
from flrjax.config import algo_config, make_env
from tests.tiny import TINY

# FLR+DHRL's sweep alpha = 0 (DHRL) and 0.01 on the point mass, 2 seeds, 2 chunks: the tiny
# run of Fig. 5's test (tests/experiments/test_figures.py) and the ablation notebooks, whose
# compiled programs the session's compilation cache then shares
SWEEP = cli.parse_cli(shlex.split(
    "--env point3leg --seeds 2 --steps 800 --preset quick --num-envs 4 --initial-episodes 4 "
    "--episodes-per-chunk 1 --hidden 16 --batch-size 32 --graph-start-steps 0 "
    "--max-landmarks 8 --landmark-sample 64 --algo flr_dhrl --flr-alpha 0,0.01 --out unused"
)).cfg


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    runner.train(dataclasses.replace(SWEEP, out=str(out)), progress=False)
    return str(out)


@pytest.fixture(scope="module")
def traced(run_dir):
    return episodes.trace_run(run_dir)


def _last_rows(run_dir: str) -> list[dict]:
    with open(f"{run_dir}/metrics.csv") as f:
        rows = list(csv.DictReader(f))
    return rows[-SWEEP.runs:]


def test_the_trace_is_the_runs_own_evaluation_at_its_newest_checkpoint(run_dir, traced):
    env = make_env(SWEEP)
    tr, n, horizon = traced.trace, SWEEP.eval_episodes, env.config.episode_length
    assert traced.chunks == 2 and traced.step == 800
    assert tr["xy"].shape == (SWEEP.runs, n, horizon, 2)
    assert tr["fallen"].shape == tr["success"].shape[:2] + (horizon,)
    # every episode starts at the env's start (within its reset noise) and moves by steps
    start = np.asarray(env.maze.start)
    assert np.abs(tr["xy"][:, :, 0] - start).max() <= env.config.reset_noise + 1e-6
    path = np.concatenate([tr["xy"], tr["final_xy"][:, :, None]], axis=2)
    assert np.linalg.norm(np.diff(path, axis=2), axis=-1).max() <= np.sqrt(2) * \
        env.config.max_speed + 1e-5
    # success is the final position's, and the episodes are those metrics.csv reports
    dist = np.linalg.norm(tr["final_xy"] - np.asarray(env.maze.goal), axis=-1)
    np.testing.assert_array_equal(tr["success"], dist <= env.config.success_radius)
    rows = _last_rows(run_dir)
    np.testing.assert_allclose(dist.mean(1), [float(r["final_goal_distance"]) for r in rows],
                               rtol=1e-5)
    np.testing.assert_allclose(traced.metrics["success_rate"],
                               [float(r["success_rate"]) for r in rows])
    assert [len(lm) for lm in traced.landmarks] == [int(float(r["graph_nodes"]))
                                                    for r in rows]
    for e, lm in zip(traced.edges, traced.landmarks, strict=True):
        assert e.shape[1:] == (2,) and e.max(initial=-1) < len(lm)


def test_the_picture_has_a_panel_per_seed_and_method_with_every_path(traced):
    fig = episodes.draw(traced)
    panels = [ax for ax in fig.axes if "seed" in ax.get_title()]
    assert len(panels) == SWEEP.runs
    titles = [ax.get_title() for ax in panels]
    assert titles[0].startswith("DHRL, seed 0:\n")
    assert titles[-1].startswith("FLR+DHRL α=0.01, seed 1:\n")
    assert titles[0].endswith("reach the goal")  # no falls: the point mass cannot fall
    for ax in panels:
        paths = [c for c in ax.collections
                 if isinstance(c, LineCollection) and c.get_array() is not None]
        assert [len(c.get_segments()) for c in paths] == [100] * SWEEP.eval_episodes
        assert ax.get_aspect() == 1.0
    assert any(ax.get_ylabel() == "env step of the episode" for ax in fig.axes)  # colour bar
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "start" in labels and "goal" in labels and "landmark graph" in labels
    assert "first fall of an episode" not in labels  # the point mass cannot fall


def test_the_command_writes_the_png_and_bad_input_gets_one_line(run_dir, tmp_path, capsys):
    episodes.main([run_dir])
    assert os.path.getsize(os.path.join(run_dir, "episodes.png")) > 0
    assert capsys.readouterr().out.strip() == f"wrote {run_dir}/episodes.png"
    empty = tmp_path / "empty"
    empty.mkdir()
    no_ckpt = tmp_path / "no_ckpt"
    no_ckpt.mkdir()
    with open(f"{run_dir}/config.json") as f:
        (no_ckpt / "config.json").write_text(json.dumps(json.load(f)))
    for argv, says in [([str(tmp_path / "missing")], "is not a directory"),
                       ([str(empty)], "config.json does not exist"),
                       ([str(no_ckpt)], "no checkpoint in"),
                       ([run_dir, "--episodes", "0"], "--episodes must be at least 1")]:
        with pytest.raises(SystemExit) as e:
            episodes.main(argv)
        err = capsys.readouterr().err.strip().splitlines()
        assert e.value.code == 2 and says in err[-1] and "Traceback" not in err[0]
        assert len(err) == 1 or err[0].startswith("usage:")


def test_seeds_pick_the_rows_and_bad_picks_get_one_line(run_dir, traced, tmp_path, capsys):
    fig = episodes.draw(traced, seeds=[1])
    titles = [ax.get_title() for ax in fig.axes if "seed" in ax.get_title()]
    assert [t.split(":")[0] for t in titles] == ["DHRL, seed 1", "FLR+DHRL α=0.01, seed 1"]
    for argv, says in [([run_dir, "--seeds", "2"], "--seeds 2: the run has 2 seeds (0 to 1)"),
                       ([run_dir, "--seeds", "0,x"], "expected seed indices like 0,2"),
                       ([run_dir, "--out", str(tmp_path / "no" / "f.png")],
                        "its directory does not exist")]:
        with pytest.raises(SystemExit) as e:
            episodes.main(argv)
        assert e.value.code == 2 and says in capsys.readouterr().err.strip().splitlines()[-1]


def test_no_video_for_the_point_mass_in_one_line(traced, tmp_path, capsys):
    assert not episodes.write_gif(traced, str(tmp_path / "a.gif"))
    assert capsys.readouterr().err.strip() == (
        f"python -m flrjax.episodes: no video: {SWEEP.env} has no MuJoCo body to render")
    assert not (tmp_path / "a.gif").exists()


def test_the_fall_marked_is_an_episodes_first():
    fallen = np.array([False, False, True, True, False, True])
    np.testing.assert_array_equal(episodes._fall_steps(fallen, True), [2])
    np.testing.assert_array_equal(episodes._fall_steps(~fallen, False), [0])
    np.testing.assert_array_equal(episodes._fall_steps(np.zeros(4, bool), True), [4])
    assert episodes._fall_steps(np.zeros(4, bool), False).size == 0


def test_an_ant_panel_marks_its_falls_in_metres():
    """The ant's drawing without training one (too slow on a CPU): a made-up trace of
    AntMaze3Leg's shape, which falls at step 10 and gets up and falls again at step 30 (only
    the first is marked)."""
    cfg = dataclasses.replace(TINY, env="ant3leg", algo="dhrl", seeds=1)
    horizon = make_env(cfg).config.episode_length
    xy = np.stack([np.linspace(0, 12, horizon), np.zeros(horizon)], -1)
    fallen = np.zeros(horizon, bool)
    fallen[10:20] = fallen[30:] = True
    trace = {"xy": xy[None, None], "fallen": fallen[None, None],
             "waypoint": np.full((1, 1, horizon, 2), 4.0),
             "subgoal": np.full((1, 1, horizon, 2), 8.0),
             "final_xy": np.array([[[12.0, 0.0]]]), "final_fallen": np.array([[True]]),
             "success": np.array([[False]])}
    ep = episodes.Episodes(cfg, 3, trace, {}, [np.array([[0.0, 0.0], [4.0, 0.0]])],
                           [np.array([[0, 1]])])
    fig = episodes.draw(ep)
    (ax,) = [ax for ax in fig.axes if "seed" in ax.get_title()]
    assert ax.get_title() == "DHRL, seed 0:\n0/1 reach the goal, 1/1 fall over"
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    red_x = [line for line in ax.get_lines() if line.get_marker() == "x"]
    np.testing.assert_allclose(red_x[0].get_xydata(), xy[[10]])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"first fall of an episode", "landmark graph", "subgoal (high level)",
            "waypoint chased (low level)"} <= set(labels)
    step = 3 * cfg.steps_per_chunk
    assert fig._suptitle.get_text() == (
        f"AntMaze3Leg: 1 evaluation episode per panel, policy at env step {step:,}")


@pytest.mark.parametrize("algo", ["flat", "pig", "higl"])
def test_every_methods_evaluation_traces_what_it_reports(algo):
    """The other methods' hooks: the trace has the episodes' shapes, starts at the env's
    start and ends where the evaluation's metrics say."""
    cfg = dataclasses.replace(TINY, algo=algo)
    env, acfg = make_env(cfg), algo_config(cfg)
    carry = algos.get(algo).init(jax.random.PRNGKey(0), env, acfg)
    key = jax.random.PRNGKey(1)
    metrics, tr = jax.jit(lambda c: algos.get(algo).evaluate(c, key, env, acfg, trace=True))(carry)
    n, horizon = cfg.eval_episodes, env.config.episode_length
    assert tr["xy"].shape == tr["waypoint"].shape == tr["subgoal"].shape == (n, horizon, 2)
    start = np.asarray(env.maze.start)
    assert np.abs(np.asarray(tr["xy"][:, 0]) - start).max() <= env.config.reset_noise + 1e-6
    dist = np.linalg.norm(np.asarray(tr["final_xy"]) - np.asarray(env.maze.goal), axis=-1)
    assert float(metrics["eval/final_goal_distance"]) == pytest.approx(dist.mean(), rel=1e-5)
