"""Sweeps: each point of a vmapped sweep trains as a plain run with its values."""

import csv
import dataclasses
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import config, run_axis, runner, sweep
from flrjax.cli import parse_args, parse_cli
from flrjax.metric_names import TIMES


def test_sweep_trains_each_value_as_its_own_run(tmp_path):
    """Two values of alpha x two of initial_episodes x 2 seeds in one vmapped run give, per
    point, the metrics of a plain run with those values (up to float rounding), also when
    stopped and resumed from the saved config (tuples, JSON lists); the CSV names each row's
    values."""
    cfg = config.make(dict(env="point3leg", algo="flr_dhrl", seeds=2, num_envs=4,
                             updates_per_step=1.0, initial_episodes=(4, 8),
                             episodes_per_chunk=1, steps=800, hidden=16, batch_size=32,
                             buffer_episodes=40, polyak=0.99, target_update_freq=1,
                             graph_start_steps=0, max_landmarks=8, landmark_sample=64,
                             flr_candidates=4, checkpoint_every=1, flr_alpha=(0.005, 0.01),
                             out=str(tmp_path / "sweep")))
    assert cfg.runs == 8 and config.sweep_points(cfg)[:2] == [
        {"flr_alpha": 0.005, "initial_episodes": 4}, {"flr_alpha": 0.005, "initial_episodes": 8}]
    runner.train(cfg, progress=False, max_chunks=1)  # stopped after a chunk, then resumed
    resumed, resume = parse_cli(["--resume", cfg.out])[:2]
    assert resume and resumed == cfg
    swept = runner.train(resumed, progress=False, resume=True)
    assert [(r["seed"], r["flr_alpha"], r["initial_episodes"]) for r in swept[-8:]] == [
        (s, a, n) for a in (0.005, 0.01) for n in (4, 8) for s in (0, 1)]
    plain = runner.train(cfg.replace(flr_alpha=0.01, initial_episodes=4, out=None),
                         progress=False)

    def point(alpha, n):
        return [r for r in swept if (r["flr_alpha"], r["initial_episodes"]) == (alpha, n)]

    for k in ("final_goal_distance", "q", "critic_loss", "reach_reward_upright"):
        np.testing.assert_allclose([r[k] for r in point(0.01, 4)], [r[k] for r in plain],
                                   rtol=1e-4, atol=1e-5, err_msg=k)
    # the values act where they should: alpha scales the reward of reaching transitions, and
    # with 8 initial episodes (2 rounds of 4 envs) the second round is still random
    assert not np.allclose([r["reach_reward_upright"] for r in point(0.005, 4)],
                           [r["reach_reward_upright"] for r in point(0.01, 4)])
    assert not np.allclose([r["critic_loss"] for r in point(0.01, 8)],
                           [r["critic_loss"] for r in point(0.01, 4)])
    with open(tmp_path / "sweep" / "metrics.csv") as f:
        table = list(csv.reader(f))
    assert table[0][:4] == ["step", "seed", "flr_alpha", "initial_episodes"]
    # the rows restored on resume keep their values as written (4, not 4.0)
    assert {row[3] for row in table[1:]} == {"4", "8"} and len(table) == 1 + 2 * 8
    cli = parse_args(["--env", "point3leg", "--algo", "flr_dhrl", "--flr-alpha",
                      "0.001,0.01", "--flr-eps", "2", "--initial-episodes", "48,96",
                      "--out", "/tmp/sweep-cli"])
    assert (cli.flr_alpha, cli.flr_eps, cli.initial_episodes) == ((0.001, 0.01), 2.0, (48, 96))


def test_listed_sweep_points_and_alpha_zero_is_dhrl(tmp_path):
    """``--sweep`` trains the listed points (fields a point leaves out keep the run's values):
    alpha 0 gives plain DHRL's metrics, since eq. (5) with alpha 0 is eq. (1), and the final
    goal as next subgoal those of a plain ``--flr-next goal`` run, also when stopped and
    resumed from config.json (nested tuples as JSON lists)."""
    cfg = config.make(dict(env="point3leg", algo="flr_dhrl", seeds=2, num_envs=4,
                             updates_per_step=1.0, initial_episodes=4, episodes_per_chunk=1,
                             steps=800, hidden=16, batch_size=32, buffer_episodes=40,
                             polyak=0.99, target_update_freq=1, graph_start_steps=0,
                             max_landmarks=8, landmark_sample=64, flr_candidates=4,
                             out=str(tmp_path / "sweep"),
                             sweep=((("flr_alpha", 0.0),), (("flr_next", "goal"),))))
    assert config.sweep_points(cfg) == [{"flr_alpha": 0.0, "flr_next": "sample"},
                                        {"flr_alpha": 0.01, "flr_next": "goal"}]
    assert parse_args(["--env", "point3leg", "--algo", "flr_dhrl", "--sweep",
                       "flr-alpha=0; flr_next=goal", "--out", "/tmp/x"]).sweep == cfg.sweep
    runner.train(cfg, progress=False, max_chunks=1)
    resumed, resume = parse_cli(["--resume", cfg.out])[:2]
    assert resume and resumed == cfg
    swept = runner.train(resumed, progress=False, resume=True)
    assert runner.build(resumed)[1]._cache_size() == 1  # one compiled chunk across the resume
    plain = {"dhrl": cfg.replace(algo="dhrl", sweep=None),
             "goal": cfg.replace(sweep=None, flr_next="goal")}
    for (name, c), next_ in zip(plain.items(), ("sample", "goal"), strict=True):
        rows = runner.train(dataclasses.replace(c, out=None), progress=False)
        point = [r for r in swept if r["flr_next"] == next_]
        assert [r["seed"] for r in point] == [r["seed"] for r in rows] == [0, 1, 0, 1]
        for k in ("final_goal_distance", "q", "critic_loss", "high_q", "graph_nodes"):
            np.testing.assert_allclose([r[k] for r in point], [r[k] for r in rows],
                                       rtol=1e-4, atol=1e-5, err_msg=f"{name} {k}")
    with open(tmp_path / "sweep" / "metrics.csv") as f:
        table = list(csv.DictReader(f))
    assert [(r["flr_alpha"], r["flr_next"]) for r in table[-4:]] == [
        ("0.0", "sample"), ("0.0", "sample"), ("0.01", "goal"), ("0.01", "goal")]


def _active_runs(cfg: config.TrainConfig) -> tuple[bool, ...] | None:
    """The program's FLR active runs (None: every run computes eq. 5, or no FLR)."""
    flr = config.program_config(cfg).flr
    return None if flr is None else flr.active_runs


def test_flr_active_runs_marks_the_runs_whose_alpha_is_positive():
    base = ["--env", "point3leg", "--seeds", "2", "--out", "/tmp/active-runs"]
    active = {a: _active_runs(parse_args([*base, *a.split()])) for a in (
        "--flr-alpha 0,0.01", "--flr-alpha 0.01", "--flr-alpha 0", "--algo dhrl",
        "--flr-alpha 0.01,0.001")}
    assert active == {"--flr-alpha 0,0.01": (False, False, True, True),
                      "--flr-alpha 0.01": None, "--flr-alpha 0": (False, False),
                      "--algo dhrl": None, "--flr-alpha 0.01,0.001": None}
    listed = parse_args([*base, "--sweep", "flr-alpha=0; flr-next=goal"])
    assert _active_runs(listed) == (False, False, True, True)


#: The repository, where ``tests`` imports from.
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: The XLA flags of the suite's unoptimised CPU backend (conftest.py): it may round two
#: different programs apart in the last bit, where XLA's default flags do not.
CHEAP_BACKEND = ("--xla_backend_optimization_level", "--xla_cpu_use_fusion_emitters")


def alpha_zero_chunks(path: str) -> None:
    """One chunk of a sweep over alpha {0, 0.01} as two programs, eq. 5's candidate values
    computed for every run and for the alpha = 0.01 runs alone: each one's low level, chunk
    metrics and FLOPs, saved to ``path`` (run in a process of its own, with XLA's default
    flags, by the test below)."""
    cfg = config.make(dict(env="point4leg", algo="flr_dhrl", seeds=2, num_envs=2,
                             steps=200, episodes_per_chunk=2, batch_size=32, hidden=16,
                             buffer_episodes=20, initial_episodes=1, graph_start_steps=200,
                             graph_every_steps=200, max_landmarks=8, landmark_sample=64,
                             eval_episodes=2, flr_alpha=(0.0, 0.01), flr_value_chunk=0))
    assert _active_runs(cfg) == (False, False, True, True)

    def chunk_of():
        init, chunk, _ = runner._build.__wrapped__(cfg)
        carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
        flops = chunk.lower(carry, jnp.int32(0)).cost_analysis()["flops"]
        carry, metrics = chunk(carry, jnp.int32(0))
        return [flops, *map(np.asarray, jax.tree.leaves((carry.low, metrics))),
                np.asarray(metrics["stats/reach_reward_upright"])]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner, "program_config", config.algo_config)  # every run computes eq. 5
        every = chunk_of()
    skip = chunk_of()
    np.savez(path, *every, *skip)


def test_alpha_zero_runs_skip_eq5_and_train_as_before(tmp_path):
    """In a sweep over alpha {0, 0.01}, eq. 5's candidate values are computed for the
    alpha = 0.01 runs alone: the chunk's FLOPs drop, the alpha = 0 runs train bit for bit as
    when every run computed them (their reward is alpha * max V = 0 either way), and the
    alpha = 0.01 runs to float rounding (the values' products run on half the runs). The
    values are taken on the whole batch, as on a GPU (the other sweep tests take the CPU's
    chunks of reaching transitions). Compiled as users compile them: XLA's default flags, in
    a process of its own (:data:`CHEAP_BACKEND`)."""
    path = str(tmp_path / "chunks.npz")
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split()
             if not f.startswith(CHEAP_BACKEND)]
    subprocess.run([sys.executable, "-c", "from tests.test_sweep import alpha_zero_chunks; "
                    f"alpha_zero_chunks({path!r})"], check=True, cwd=ROOT,
                   env={**os.environ, "XLA_FLAGS": " ".join(flags)})
    saved = np.load(path)
    arrays = [saved[f"arr_{i}"] for i in range(len(saved.files))]
    every, skip = arrays[:len(arrays) // 2], arrays[len(arrays) // 2:]
    assert skip[0] < 0.9 * every[0]
    for a, b in zip(skip[1:-1], every[1:-1], strict=True):
        np.testing.assert_array_equal(a[:2], b[:2])  # alpha = 0: DHRL, bit for bit
        np.testing.assert_allclose(a[2:], b[2:], rtol=1e-5, atol=1e-6)
    assert np.any(skip[-1][2:] != 0)  # FLR did act


def _learner_sweep_base(tmp_path) -> list[str]:
    return ["--env", "point3leg", "--algo", "flat", "--preset", "quick", "--seeds", "2",
            "--steps", "800", "--episodes-per-chunk", "1", "--initial-episodes", "4",
            "--hidden", "16", "--batch-size", "32", "--buffer-episodes", "20",
            "--eval-episodes", "2", "--checkpoint-every", "0", "--out", str(tmp_path / "run")]


def _initial_hparams(cfg: config.TrainConfig):
    """Every run's learner numbers as its initial carry holds them."""
    init = runner.build(cfg)[0]
    return init(run_axis.run_keys(cfg, jax.random.PRNGKey(0))).agent.hp


def _metrics(rows: list[dict], point: dict) -> dict[str, np.ndarray]:
    """The rows of ``point`` (all rows for ``{}``) by metric, without the swept columns and
    the timings."""
    rows = [r for r in rows if all(r[k] == v for k, v in point.items())]
    return {k: np.array([r[k] for r in rows]) for k in rows[0]
            if k not in (*point, *TIMES)}


@pytest.mark.parametrize("flags, points", [
    (["--lr-critic", "3e-4,1e-3"], [{"lr_critic": 3e-4}, {"lr_critic": 1e-3}]),
    (["--sweep", "polyak=0.9; noise-eps=0.3, polyak=0.995"],
     [{"polyak": 0.9, "noise_eps": 0.1}, {"polyak": 0.995, "noise_eps": 0.3}]),
])
def test_learner_numbers_sweep_as_points_of_one_program(tmp_path, flags, points):
    """A learning rate (a comma list), the Polyak rate and the exploration noise (--sweep
    points) are traced per run: 2 seeds of each point train in one program as a run of that
    point's values alone does. Each run's agents start with the numbers a plain run of its
    point has, bit for bit (built from the point's Python numbers), and compute with them
    as it does; the metrics agree up to float rounding (rtol 1e-4, as for the alpha sweep):
    XLA's CPU kernels over a batch of 4 runs may order a sum otherwise than over 2, and a
    chunk compounds that last bit. The CSV names each row's values; the points differ."""
    swept = parse_args([*_learner_sweep_base(tmp_path), *flags])
    assert swept.runs == 4 and config.sweep_points(swept) == points
    rows = runner.train(swept, progress=False)
    with open(tmp_path / "run" / "metrics.csv") as f:
        assert next(csv.reader(f))[2:2 + len(points[0])] == list(points[0])
    for i, point in enumerate(points):
        alone = parse_args([*_learner_sweep_base(tmp_path / f"alone{i}"),
                            *(x for k, v in point.items()
                              for x in ("--" + k.replace("_", "-"), str(v)))])
        runs = slice(2 * i, 2 * i + 2)
        for x, y in zip(jax.tree.leaves(_initial_hparams(swept)),
                        jax.tree.leaves(_initial_hparams(alone)), strict=True):
            np.testing.assert_array_equal(x[runs], y)
        want = _metrics(runner.train(alone, progress=False), {})
        got = _metrics(rows, point)
        assert got.keys() == want.keys() and len(got["step"]) == 4
        for k in want:
            np.testing.assert_allclose(got[k], want[k], rtol=1e-4, atol=1e-5,
                                       err_msg=f"{point} {k}")
    first, second = (_metrics(rows, p) for p in points)
    assert not np.array_equal(first["critic_loss"], second["critic_loss"])


def test_exploration_numbers_reach_each_points_agents():
    """--random-eps (the low level's random actions) and --subgoal-noise-eps (the high level's
    subgoal noise, in maze units: noise_eps times the box's larger half-extent, 12 in the
    point U-maze) are per-run numbers of one program; unset, DHRL's subgoal noise is 2 and
    HIGL's manager noise 1, as before the flag."""
    base = ["--env", "point4leg", "--seeds", "2", "--out", "/tmp/never-made"]
    cfg = parse_args([*base, "--algo", "dhrl", "--subgoal-noise-eps", "1,4",
                      "--random-eps", "0.05"])
    hp = sweep.run_hparams(cfg)
    np.testing.assert_allclose(hp["high"].noise_eps * 12.0, [1, 1, 4, 4], rtol=1e-6)
    np.testing.assert_allclose(hp["low"].random_eps, 0.05, rtol=1e-6)
    assert runner._shape_key(cfg) == runner._shape_key(cfg.replace(subgoal_noise_eps=(2.0, 3.0)))
    for algo, noise in (("dhrl", 2.0), ("higl", 1.0)):
        hp = sweep.run_hparams(parse_args([*base, "--algo", algo]))
        np.testing.assert_allclose(hp["high"].noise_eps * 12.0, noise, rtol=1e-6)
        np.testing.assert_allclose(hp["low"].random_eps, 0.2, rtol=1e-6)


def test_graph_numbers_sweep_as_points_of_one_program(tmp_path):
    """The landmark graph's edge cutoff and FPS spacing (--sweep points; a point that leaves
    one unset takes the env's default: 6 and 3 on the point mass) are each run's traced values
    in the method's config: a point trains in the program as a run of its values alone (up to
    float rounding, as above), and a shorter cutoff leaves some plans unfound."""
    def base(out):
        return ["--env", "point3leg", "--algo", "dhrl", "--seeds", "1", "--steps", "800",
                "--episodes-per-chunk", "1", "--initial-episodes", "4", "--hidden", "16",
                "--batch-size", "32", "--buffer-episodes", "20", "--eval-episodes", "2",
                "--checkpoint-every", "0", "--graph-start-steps", "0", "--max-landmarks", "8",
                "--landmark-sample", "64", "--out", str(out)]

    points = [{"cutoff": 2.0, "landmark_eps": 3.0}, {"cutoff": 6.0, "landmark_eps": 0.5}]
    swept = parse_args([*base(tmp_path / "run"), "--sweep", "cutoff=2; landmark-eps=0.5"])
    assert swept.runs == 2 and config.sweep_points(swept) == points
    second = config.algo_config(swept, points[1])
    assert (second.cutoff, second.stop_eps) == (6.0, 0.5)
    rows = runner.train(swept, progress=False)
    alone = parse_args([*base(tmp_path / "alone"), "--cutoff", "2"])
    want, got = _metrics(runner.train(alone, progress=False), {}), _metrics(rows, points[0])
    assert got.keys() == want.keys() and len(got["step"]) == 2
    for k in want:
        np.testing.assert_allclose(got[k], want[k], rtol=1e-4, atol=1e-5, err_msg=k)
    assert got["plan_found_frac"][-1] < _metrics(rows, points[1])["plan_found_frac"][-1]
