"""The trainer on the point-mass maze: learning, reproducibility, no recompilation, bad input."""

import csv
import dataclasses
import json
import os
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import train

# the quick preset's sizes with the flat learner and chunks of 4,000 steps
QUICK = train.TrainConfig(env="point3leg", **{**train.PRESETS["quick"], "algo": "flat",
                                              "steps": 24_000, "episodes_per_chunk": 10})
TINY = dataclasses.replace(QUICK, steps=400, episodes_per_chunk=1, initial_episodes=4,
                           eval_episodes=2)


def test_flat_learner_reaches_nearby_goals_for_two_vmapped_seeds():
    cfg = dataclasses.replace(QUICK, seeds=2, steps=12_000)
    rows = train.train(cfg, progress=False)
    last = [r for r in rows if r["step"] == cfg.steps]
    assert len(last) == 2
    for r in last:  # deterministic policy, 10 goals drawn as in training, within 5 at the end
        assert r["random_goal_success"] >= 0.8, r
        assert np.isfinite(r["critic_loss"]) and r["falls"] == 0


def test_same_seed_same_metrics_and_one_compilation(tmp_path):
    a = train.train(dataclasses.replace(TINY, seeds=2, out=str(tmp_path / "a")), progress=False)
    b = train.train(dataclasses.replace(TINY, seeds=2, out=str(tmp_path / "b")), progress=False)
    c = train.train(dataclasses.replace(TINY, seeds=2, seed=1), progress=False)
    drop = ("wall_time", "env_steps_per_s")
    strip = [{k: v for k, v in r.items() if k not in drop} for r in a]
    assert strip == [{k: v for k, v in r.items() if k not in drop} for r in b]
    assert strip != [{k: v for k, v in r.items() if k not in drop} for r in c]
    assert len(a) == 2 * (TINY.steps // TINY.steps_per_chunk)
    # three runs, several chunks each: the chunk was compiled once
    _, chunk, evaluate = train.build(dataclasses.replace(TINY, seeds=2))
    assert chunk._cache_size() == 1 and evaluate._cache_size() == 1
    with open(tmp_path / "a" / "metrics.csv") as f:
        written = list(csv.DictReader(f))
    assert len(written) == len(a) and set(written[0]) == set(train.metric_fields("flat"))
    assert os.path.exists(tmp_path / "a" / "config.json")


def test_out_dir_holding_another_run_is_refused(tmp_path):
    train.prepare_out(dataclasses.replace(TINY, out=str(tmp_path)))
    with pytest.raises(train.ConfigError, match="already holds a run with a different config"):
        train.prepare_out(dataclasses.replace(TINY, out=str(tmp_path), seeds=3))


@pytest.mark.parametrize("argv,message", [
    (["--env", "nope"], "unknown env 'nope'"),
    (["--algo", "ppo"], "unknown algo 'ppo'"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--steps", "1001"], "must be a multiple of"),
    (["--num-envs", "3", "--updates-per-step", "0.5"], "must be a positive integer"),
    (["--buffer-episodes", "2", "--num-envs", "4"], "--buffer-episodes"),
    (["--seeds", "two"], "invalid int value"),
    (["--polyak", "1.5"], "--polyak must be in [0, 1)"),
    (["--subgoal-freq", "10"], "--subgoal-freq applies to the graph algos"),
    (["--algo", "dhrl", "--subgoal-freq", "7"], "must divide the episode length"),
    (["--algo", "dhrl", "--flr-alpha", "0.01"], "applies to the flr_* algos only"),
    (["--algo", "flr_dhrl", "--flr-alpha", "-0.01"], "FLR needs alpha >= 0"),
    (["--algo", "flr_dhrl", "--flr-next", "far"], "--flr-next must be 'sample' or 'goal'"),
    (["--algo", "dhrl", "--max-landmarks", "500", "--landmark-sample", "100"],
     "--max-landmarks (500) must be <="),
    (["--checkpoint-every", "-1"], "--checkpoint-every must be >= 0"),
    (["--batch-size", "5000", "--buffer-episodes", "4"], "larger than the replay buffer"),
    (["--flr-eps", "nan", "--algo", "flr_dhrl"], "must be a finite number"),
    (["--algo", "dhrl", "--flr-alpha", "0.01,0.1"], "applies to the flr_* algos only"),
    (["--algo", "flr_dhrl", "--flr-alpha", "0.01,0.01"], "a sweep needs distinct values"),
    (["--algo", "flr_dhrl", "--flr-alpha", "0.01,-1"], "FLR needs alpha >= 0"),
    (["--algo", "flr_dhrl", "--flr-next", "goal", "--flr-eps", "1,2"], "means nothing"),
    (["--algo", "flr_dhrl", "--flr-alpha", "0.01,x"], "invalid _floats value"),
    (["--initial-episodes", "4,-1"], "--initial-episodes must be >= 0"),
    (["--initial-episodes", "4,4"], "a sweep needs distinct values"),
    (["--algo", "flr_dhrl", "--sweep", "flr-alpha=0; polyak=0.9"], "each point is FIELD=VALUE"),
    (["--algo", "flr_dhrl", "--sweep", "flr-alpha=x"], "not a number"),
    (["--algo", "flr_dhrl", "--sweep", "flr-alpha=0.01; flr-eps=2"], "the points must differ"),
    (["--algo", "flr_dhrl", "--sweep", "flr-eps=1", "--flr-alpha", "0,0.01"],
     "--sweep lists every point"),
    (["--algo", "dhrl", "--sweep", "flr-alpha=0"], "applies to the flr_* algos only"),
    (["--algo", "flr_dhrl", "--sweep", "flr-next=far"], "--flr-next must be 'sample' or"),
    (["--algo", "flr_dhrl", "--sweep", "initial-episodes=-1"], "must be >= 0, got -1"),
    (["--algo", "flr_dhrl", "--sweep", ";"], "--sweep needs at least one point"),
])
def test_bad_flags_give_one_line_errors(argv, message, capsys):
    with pytest.raises(SystemExit) as e:
        train.parse_args(["--env", "point3leg", "--algo", "flat", *argv])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and "Traceback" not in "\n".join(err)


def test_presets_and_overrides():
    cfg = train.parse_args(["--env", "point4leg", "--preset", "quick", "--seeds", "3",
                            "--out", "/tmp/x"])
    assert cfg.seeds == 3 and cfg.hidden == train.PRESETS["quick"]["hidden"]
    assert cfg.steps % cfg.steps_per_chunk == 0
    paper = train.parse_args(["--env", "ant4leg", "--preset", "paper", "--out", "/tmp/y"])
    assert (paper.num_envs, paper.updates_per_iter, paper.batch_size) == (1, 1, 1024)


def test_killed_run_resumes_to_identical_metrics(tmp_path):
    cfg = dataclasses.replace(TINY, seeds=2, steps=4 * TINY.steps_per_chunk)
    whole = train.train(dataclasses.replace(cfg, out=str(tmp_path / "whole")), progress=False)
    out = str(tmp_path / "cut")
    train.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=2)
    # a row written after the last checkpoint (as if killed between the two) is dropped
    with open(os.path.join(out, "metrics.csv"), "a") as f:
        f.write(",".join(["999"] * len(train.metric_fields("flat"))) + "\n")
    resumed_cfg, resume = train.parse_cli(["--resume", out])[:2]
    assert resume and resumed_cfg == dataclasses.replace(cfg, out=out)
    rows = train.train(resumed_cfg, progress=False, resume=True)
    # the restored carry has the fresh one's types: one compiled chunk for all three runs
    _, chunk, evaluate = train.build(cfg)
    assert chunk._cache_size() == 1 and evaluate._cache_size() == 1
    drop = ("wall_time", "env_steps_per_s")
    assert [{k: v for k, v in r.items() if k not in drop} for r in rows] == \
        [{k: v for k, v in r.items() if k not in drop} for r in whole]
    with open(os.path.join(out, "metrics.csv")) as f:
        assert len(list(csv.DictReader(f))) == len(whole)
    assert sorted(os.listdir(os.path.join(out, "checkpoints"))) == ["chunk_000003",
                                                                   "chunk_000004"]
    with pytest.raises(SystemExit):
        train.parse_cli(["--resume", out, "--seeds", "3"])


def test_time_limit_stops_with_a_checkpoint_and_resume_finishes(tmp_path):
    cfg = dataclasses.replace(TINY, steps=2 * TINY.steps_per_chunk, checkpoint_every=0,
                              out=str(tmp_path / "run"))
    # any limit shorter than a chunk stops after the first one, checkpointed although
    # checkpoint_every=0 keeps none otherwise
    rows = train.train(cfg, progress=False, time_limit=1e-6)
    assert [r["step"] for r in rows] == [TINY.steps_per_chunk] * cfg.seeds
    assert os.listdir(os.path.join(cfg.out, "checkpoints")) == ["chunk_000001"]
    resumed_cfg, resume, limit = train.parse_cli(["--resume", cfg.out, "--time-limit", "600"])[:3]
    assert resume and limit == 600.0 and resumed_cfg == cfg
    rows = train.train(resumed_cfg, progress=False, resume=True, time_limit=limit)
    assert rows[-1]["step"] == cfg.steps and len(rows) == 2 * cfg.seeds
    for bad in ("0", "-5", "nan"):
        with pytest.raises(SystemExit):
            train.parse_cli(["--env", "point4leg", "--time-limit", bad])


def test_progress_fn_sees_every_chunk_and_can_end_the_run(tmp_path):
    cfg = dataclasses.replace(TINY, steps=3 * TINY.steps_per_chunk, out=str(tmp_path / "run"))
    seen = []

    def progress(step, rows):
        seen.append((step, len(rows)))
        return step >= 2 * TINY.steps_per_chunk  # e.g. a target success reached

    rows = train.train(cfg, progress=False, progress_fn=progress)
    n = TINY.steps_per_chunk
    assert seen == [(n, cfg.seeds), (2 * n, cfg.seeds)]
    assert rows[-1]["step"] == 2 * n and len(rows) == 2 * cfg.seeds
    assert sorted(os.listdir(os.path.join(cfg.out, "checkpoints"))) == [
        "chunk_000001", "chunk_000002"]  # checkpoint_every=1, as without the hook


def test_compile_cache_is_on_by_default_in_the_users_cache_dir(monkeypatch):
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "/x/cache")
    assert train.default_compile_cache() == "/x/cache/flrjax/jax"
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", "/y/jit")
    assert train.default_compile_cache() == "/y/jit"
    base = ["--env", "point4leg", "--out", "/tmp/cache-flag"]
    assert train.parse_cli(base).compile_cache == "/y/jit"
    assert train.parse_cli([*base, "--no-compile-cache"]).compile_cache is None


def test_flr_warns_when_alpha_exceeds_one_minus_gamma():
    with pytest.warns(UserWarning, match="eq. \\(4\\) no longer guarantees"):
        train.parse_args(["--env", "point4leg", "--algo", "flr_dhrl", "--flr-alpha", "0.1",
                          "--out", "/tmp/flr-warn"])
    with pytest.warns(UserWarning, match="eq. \\(6\\)"):
        train.parse_args(["--env", "point4leg", "--algo", "flr_dhrl", "--flr-eps", "0.5",
                          "--out", "/tmp/flr-warn"])


def test_flr_value_chunk_flag_reaches_the_flr_config():
    """--flr-value-chunk: unset is FLRConfig's 128 on a CPU, 0 the whole batch (None), N
    chunks of N; --flr-precision: unset is float32 on a CPU."""
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/flr-value-chunk"]
    for argv, want in (([], 128), (["--flr-value-chunk", "0"], None),
                       (["--flr-value-chunk", "256"], 256)):
        cfg = train.parse_args([*base, *argv])
        assert train.flr_config(cfg).value_chunk == want, argv
        assert train.algo_config(cfg).flr.value_chunk == want, argv
        assert train.flr_config(cfg).value_dtype == "float32"
    pig = train.parse_args([*base, "--algo", "flr_pig", "--flr-value-chunk", "0"])
    assert train.algo_config(pig).base.flr.value_chunk is None


def test_flr_evaluates_the_whole_batch_in_bf16_by_default_on_a_gpu(monkeypatch):
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/flr-value-chunk"]
    monkeypatch.setattr(train.jax, "default_backend", lambda: "gpu")
    flr = train.flr_config(train.parse_args(base))
    assert flr.value_chunk is None and flr.value_dtype == "bfloat16"
    flr = train.flr_config(train.parse_args([*base, "--flr-value-chunk", "128",
                                             "--flr-precision", "float32"]))
    assert flr.value_chunk == 128 and flr.value_dtype == "float32"


@pytest.mark.parametrize("argv,message", [
    (["--algo", "flr_dhrl", "--flr-value-chunk", "-1"], "--flr-value-chunk must be >= 0"),
    (["--algo", "dhrl", "--flr-value-chunk", "64"], "applies to the flr_* algos only"),
    (["--algo", "flr_dhrl", "--flr-value-chunk", "64,128"], "invalid int value"),
    (["--algo", "flr_dhrl", "--sweep", "flr-value-chunk=64"], "each point is FIELD=VALUE"),
])
def test_flr_value_chunk_bad_values_give_one_line_errors(argv, message, capsys):
    test_bad_flags_give_one_line_errors(argv, message, capsys)


def test_flr_value_chunk_saved_only_when_set_and_old_configs_resume(tmp_path):
    """Unset, it is not in config.json (old runs' configs compare equal); a config.json
    without it resumes with None; a set value is saved and resumed."""
    cfg = dataclasses.replace(TINY, algo="flr_dhrl")
    assert "flr_value_chunk" not in train.config_dict(cfg)
    assert train.config_dict(dataclasses.replace(cfg, flr_value_chunk=0))["flr_value_chunk"] == 0
    for chunk in (None, 0, 64):
        out = str(tmp_path / f"run{chunk}")
        train.prepare_out(dataclasses.replace(cfg, out=out, flr_value_chunk=chunk))
        resumed, resume = train.parse_cli(["--resume", out])[:2]
        assert resume and resumed.flr_value_chunk == chunk
        assert train.flr_config(resumed).value_chunk == (128 if chunk is None else chunk or None)
    with pytest.raises(SystemExit):  # a resumed run keeps its own chunk
        train.parse_cli(["--resume", str(tmp_path / "runNone"), "--flr-value-chunk", "0"])


def test_flr_dhrl_runs_end_to_end_and_logs_the_reward_gap(tmp_path):
    cfg = dataclasses.replace(TINY, env="point4leg", algo="flr_dhrl", seeds=2, steps=1200,
                              episodes_per_chunk=1, hidden=16, batch_size=32,
                              graph_start_steps=400, graph_every_steps=800, max_landmarks=8,
                              landmark_sample=64, flr_candidates=4, out=str(tmp_path))
    rows = train.train(cfg, progress=False)
    assert [r["step"] for r in rows] == [400, 400, 800, 800, 1200, 1200]
    last = rows[-1]
    assert last["graph_nodes"] >= 1 and np.isfinite(last["critic_loss"])
    # the point mass never falls: every reaching transition is upright, the gap has no data
    assert last["reach_fallen_frac"] == 0.0 and np.isnan(last["reward_gap"])
    assert -1.0 <= last["reach_reward_upright"] <= 0.0
    assert 0.0 < last["reach_frac"] < 1.0  # some HER transitions reach their subgoal, not all
    with open(tmp_path / "metrics.csv") as f:
        assert set(next(csv.DictReader(f))) == set(train.metric_fields("flr_dhrl"))


def test_flr_on_reaching_transitions_only_trains_like_flr_on_all(tmp_path):
    """V evaluated on the reaching transitions only, 8 at a time (batch 32), trains as V on
    every transition (--flr-value-chunk 0) does: the rewards are the same, so are the metrics
    (up to float)."""
    cfg = dataclasses.replace(TINY, env="point4leg", algo="flr_dhrl", steps=800,
                              episodes_per_chunk=1, hidden=16, batch_size=32,
                              graph_start_steps=400, graph_every_steps=800, max_landmarks=8,
                              landmark_sample=64, flr_candidates=4)
    runs = {chunk: train.train(dataclasses.replace(cfg, flr_value_chunk=chunk,
                                                   out=str(tmp_path / f"{chunk}")),
                               progress=False) for chunk in (0, 8)}
    assert 0.0 < runs[8][-1]["reach_frac"] < 1.0
    for k in ("critic_loss", "q", "reach_frac", "reach_reward_upright", "final_goal_distance",
              "high_q"):
        np.testing.assert_allclose([r[k] for r in runs[8]], [r[k] for r in runs[0]],
                                   rtol=1e-4, atol=1e-5, err_msg=k)


def test_sweep_trains_each_value_as_its_own_run(tmp_path):
    """Two values of alpha x two of initial_episodes x 2 seeds in one vmapped run give, per
    point, the metrics of a plain run with those values (up to float rounding), also when
    stopped and resumed from the saved config (tuples, JSON lists); the CSV names each row's
    values."""
    cfg = train.TrainConfig(env="point3leg", algo="flr_dhrl", seeds=2, num_envs=4,
                            updates_per_step=1.0, initial_episodes=(4, 8),
                            episodes_per_chunk=1, steps=800, hidden=16, batch_size=32,
                            buffer_episodes=40, polyak=0.99, target_update_freq=1,
                            graph_start_steps=0, max_landmarks=8, landmark_sample=64,
                            flr_candidates=4, checkpoint_every=1, flr_alpha=(0.005, 0.01),
                            out=str(tmp_path / "sweep"))
    assert cfg.runs == 8 and train.sweep_points(cfg)[:2] == [
        {"flr_alpha": 0.005, "initial_episodes": 4}, {"flr_alpha": 0.005, "initial_episodes": 8}]
    train.train(cfg, progress=False, max_chunks=1)  # stopped after a chunk, then resumed
    resumed, resume = train.parse_cli(["--resume", cfg.out])[:2]
    assert resume and resumed == cfg
    swept = train.train(resumed, progress=False, resume=True)
    assert [(r["seed"], r["flr_alpha"], r["initial_episodes"]) for r in swept[-8:]] == [
        (s, a, n) for a in (0.005, 0.01) for n in (4, 8) for s in (0, 1)]
    plain = train.train(dataclasses.replace(cfg, flr_alpha=0.01, initial_episodes=4, out=None),
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
    cli = train.parse_args(["--env", "point3leg", "--algo", "flr_dhrl", "--flr-alpha",
                            "0.001,0.01", "--flr-eps", "2", "--initial-episodes", "48,96",
                            "--out", "/tmp/sweep-cli"])
    assert (cli.flr_alpha, cli.flr_eps, cli.initial_episodes) == ((0.001, 0.01), 2.0, (48, 96))


def test_listed_sweep_points_and_alpha_zero_is_dhrl(tmp_path):
    """``--sweep`` trains the listed points (fields a point leaves out keep the run's values):
    alpha 0 gives plain DHRL's metrics, since eq. (5) with alpha 0 is eq. (1), and the final
    goal as next subgoal those of a plain ``--flr-next goal`` run, also when stopped and
    resumed from config.json (nested tuples as JSON lists)."""
    cfg = train.TrainConfig(env="point3leg", algo="flr_dhrl", seeds=2, num_envs=4,
                            updates_per_step=1.0, initial_episodes=4, episodes_per_chunk=1,
                            steps=800, hidden=16, batch_size=32, buffer_episodes=40,
                            polyak=0.99, target_update_freq=1, graph_start_steps=0,
                            max_landmarks=8, landmark_sample=64, flr_candidates=4,
                            out=str(tmp_path / "sweep"),
                            sweep=((("flr_alpha", 0.0),), (("flr_next", "goal"),)))
    assert train.sweep_points(cfg) == [{"flr_alpha": 0.0, "flr_next": "sample"},
                                       {"flr_alpha": 0.01, "flr_next": "goal"}]
    assert train.parse_args(["--env", "point3leg", "--algo", "flr_dhrl", "--sweep",
                             "flr-alpha=0; flr_next=goal", "--out", "/tmp/x"]).sweep == cfg.sweep
    train.train(cfg, progress=False, max_chunks=1)
    resumed, resume = train.parse_cli(["--resume", cfg.out])[:2]
    assert resume and resumed == cfg
    swept = train.train(resumed, progress=False, resume=True)
    assert train.build(resumed)[1]._cache_size() == 1  # one compiled chunk across the resume
    plain = {"dhrl": dataclasses.replace(cfg, algo="dhrl", sweep=None, flr_candidates=None),
             "goal": dataclasses.replace(cfg, sweep=None, flr_next="goal")}
    for (name, c), next_ in zip(plain.items(), ("sample", "goal"), strict=True):
        rows = train.train(dataclasses.replace(c, out=None), progress=False)
        point = [r for r in swept if r["flr_next"] == next_]
        assert [r["seed"] for r in point] == [r["seed"] for r in rows] == [0, 1, 0, 1]
        for k in ("final_goal_distance", "q", "critic_loss", "high_q", "graph_nodes"):
            np.testing.assert_allclose([r[k] for r in point], [r[k] for r in rows],
                                       rtol=1e-4, atol=1e-5, err_msg=f"{name} {k}")
    with open(tmp_path / "sweep" / "metrics.csv") as f:
        table = list(csv.DictReader(f))
    assert [(r["flr_alpha"], r["flr_next"]) for r in table[-4:]] == [
        ("0.0", "sample"), ("0.0", "sample"), ("0.01", "goal"), ("0.01", "goal")]


SHARDED_SCRIPT = """
import dataclasses, json
import jax, jax.numpy as jnp, numpy as np
from flrjax import train
assert jax.device_count() == 4, jax.devices()
cfg = train.TrainConfig(env="point3leg", algo="flat", **{**train.PRESETS["quick"], "steps": 800,
                        "episodes_per_chunk": 1, "initial_episodes": 4, "eval_episodes": 2,
                        "seeds": 4})
def params(agent):  # [seeds, all float parameters]
    return np.concatenate([np.asarray(x, np.float64).reshape(cfg.seeds, -1)
                           for x in jax.tree.leaves(agent)
                           if jnp.issubdtype(x.dtype, jnp.floating)], 1)
before, after, random_round, split, compiles = {}, {}, {}, {}, {}
for devices in (4, 1):
    c = dataclasses.replace(cfg, devices=devices)
    init, chunk, _ = train.build(c)
    carry = train.init_carry(c, init, jax.random.PRNGKey(0))
    split[devices] = all(x.sharding.is_equivalent_to(train.shard_seeds(c), x.ndim)
                         for x in jax.tree.leaves(carry))
    carry, _ = chunk(carry, jnp.int32(0))  # a random-action round: no learning
    random_round[devices] = jax.tree.map(np.asarray, (carry.buffer, carry.env_state.obs))
    before[devices] = params(carry.agent)
    carry, _ = chunk(carry, jnp.int32(1))  # a round of 400 updates
    after[devices] = params(carry.agent)
    compiles[devices] = chunk._cache_size()
    if devices == 4:
        leaves = [x.sharding.device_set for x in jax.tree.leaves(carry) if hasattr(x, "sharding")]
move = after[1] - before[1]
own = move - move.mean(0)  # each seed's learning less what all seeds learned alike
norm = lambda x: np.linalg.norm(x, axis=1)
same = lambda a, b: all(np.array_equal(x, y)
                        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))
print(json.dumps({"devices": max(len(d) for d in leaves),
                  "same_buffer_after_random_round": same(random_round[4], random_round[1]),
                  "same_params_after_random_round": same(before[4], before[1]),
                  "diff_over_move": (norm(after[4] - after[1]) / norm(move)).tolist(),
                  "own_over_move": (norm(own) / norm(move)).tolist(),
                  "nearest_unsharded": [int(np.argmin(norm(after[1] - a))) for a in after[4]],
                  "auto": train.num_devices(cfg), "split_along_seeds": all(split.values()),
                  "chunk_compiles": list(compiles.values())}))
"""


def _avals(tree) -> dict[str, tuple]:
    """Shape, dtype and weak type of each leaf, by path: what a jitted function's cache is
    keyed on."""
    return {jax.tree_util.keystr(p): (x.shape, x.dtype, x.weak_type)
            for p, x in jax.tree_util.tree_leaves_with_path(tree)}


@pytest.mark.parametrize("algo", list(train.ALGOS))
def test_carry_is_strongly_typed_and_the_chunk_keeps_its_types(algo):
    """Traced only. No leaf of the initial carry is weakly typed (as one made from a bare
    Python 0.0 is): a checkpoint restores every leaf strongly typed, and the chunk would
    compile again for the restored carry. And a chunk returns the carry with the types it
    took, or the next chunk would compile again (so init alone cannot fix a weak leaf)."""
    init, chunk, _ = train.build(dataclasses.replace(TINY, algo=algo))
    carry = jax.eval_shape(init, jax.ShapeDtypeStruct((1, 2), jnp.uint32))
    assert not [path for path, (_, _, weak) in _avals(carry).items() if weak]
    out, _ = jax.eval_shape(chunk, carry, jax.ShapeDtypeStruct((), jnp.int32))
    assert _avals(out) == _avals(carry)


def test_seeds_sharded_over_four_devices_train_as_unsharded():
    """Run in a fresh process: the forced CPU device count must be set before JAX starts.

    The same up to float rounding, not bit for bit: with one seed per device instead of four,
    XLA fuses and orders the reductions differently (which kernels, and so how far apart, depends
    on the CPU: 0.06 at most on one with AMX, 1e-5 on others), and Adam amplifies rounding (it
    normalises near-zero gradients). So: bit-identical data and parameters after a round
    without learning; after a round of 400 updates each seed's parameters are nearest its own
    unsharded seed, and far nearer than their learning moved them. The bound is relative to
    that movement, not one machine's rounding: anything shared across seeds (gradients averaged
    over devices, say) would move a seed away by its own part of the learning, which the test
    measures as at least half of the movement; rounding stays under a tenth of it (0.044 at
    most on the AMX machine). (For a fixed device count a run is bit-reproducible:
    test_same_seed_same_metrics_and_one_compilation.)"""
    import subprocess
    import sys

    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=4"}
    res = subprocess.run([sys.executable, "-c", SHARDED_SCRIPT], env=env, capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["auto"] == 4 and out["devices"] == 4  # the carry lives on all four
    # every leaf split along seeds (none replicated), so the chunk compiled once, not again
    # when its sharded output came back as input
    assert out["split_along_seeds"] and out["chunk_compiles"] == [1, 1], out
    assert out["same_buffer_after_random_round"] and out["same_params_after_random_round"], out
    assert out["nearest_unsharded"] == [0, 1, 2, 3], out
    assert min(out["own_over_move"]) > 0.5, out  # the bound below can tell sharing apart
    assert max(out["diff_over_move"]) < 0.25, out


def test_fuzzed_command_lines_never_show_a_traceback(capsys):
    """Random flag lists (valid, out-of-range and malformed values, unknown flags) either parse
    to a valid config or exit with argparse's one-line usage error (code 2)."""
    rng = np.random.default_rng(0)
    flags = ["--" + k.replace("_", "-") for k in train.FLAG_HELP] + [
        "--env", "--algo", "--seeds", "--seed", "--preset", "--bogus"]
    values = ["0", "-1", "1", "3", "7", "100", "0.5", "1e9", "-0.01", "nan", "inf", "abc", "",
              "point4leg", "point3leg", "nope", "flat", "dhrl", "flr_dhrl", "quick", "goal"]
    for _ in range(300):
        argv = ["--env", "point4leg", "--out", "/tmp/fuzz-never-written"]
        for _ in range(rng.integers(1, 5)):
            argv += [str(rng.choice(flags)), str(rng.choice(values))]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cfg = train.parse_args(argv)
        except SystemExit as e:
            assert e.code == 2, argv
            err = capsys.readouterr().err.strip().splitlines()
            assert err and "Traceback" not in "\n".join(err), argv
            assert err[-1].startswith("python -m flrjax.train: error:"), (argv, err[-1])
        else:
            train.validate(cfg)  # what parsed is valid


TRIPOD_SCRIPT = """
import json, sys
import jax, numpy as np
from flrjax import train
cfg = train.TrainConfig(env="ant3leg", algo="flr_dhrl", seeds=1, num_envs=1, steps=80,
                        episodes_per_chunk=1, episode_length=40, subgoal_freq=20,
                        batch_size=16, hidden=16, buffer_episodes=4, initial_episodes=1,
                        eval_episodes=1, graph_start_steps=40, graph_every_steps=40,
                        max_landmarks=4, landmark_sample=16, flr_candidates=2, out=sys.argv[1])
rows = train.train(cfg, progress=False)
init, chunk, evaluate = train.build(cfg)
template = init(jax.random.split(jax.random.PRNGKey(0), 1))
done, carry, saved_rows = train._restore(cfg, template)
kernel = lambda c: c.low.actor_params["params"]["MLP_0"]["TorchDense_0"]["kernel"]
print(json.dumps({
    "steps": [r["step"] for r in rows],
    "last": {k: float(rows[-1][k]) for k in ("graph_nodes", "critic_loss", "final_torso_z",
                                               "falls", "final_goal_distance",
                                               "env_steps_per_s")},
    "compiles": [chunk._cache_size(), evaluate._cache_size()],
    "weak_leaves": sum(x.weak_type for x in jax.tree.leaves(template)),
    "restored_chunks": done, "restored_rows": len(saved_rows),
    "same_structure": jax.tree.structure(carry) == jax.tree.structure(template),
    "restored_params_differ": not np.array_equal(kernel(carry), kernel(template))}))
"""


def test_short_flr_dhrl_run_on_the_tripod_ant(tmp_path):
    """The MJX ant through the whole hierarchical step: a random round, then a round that
    plans on a graph, learns with the FLR and evaluates. Tiny sizes: this is the CPU smoke
    test, the learning is measured on a GPU.

    In a fresh process, without the session's compilation cache: in the full CPU suite (not
    alone) jaxlib 0.10.2 crashed several times (SIGABRT, SIGSEGV) compiling this chunk or
    serialising it into the cache, at different points of the test."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    res = subprocess.run([sys.executable, "-c", TRIPOD_SCRIPT, str(tmp_path)], env=env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["steps"] == [40, 80]
    last = out["last"]
    assert last["graph_nodes"] >= 1 and np.isfinite(last["critic_loss"])
    assert 0.0 < last["final_torso_z"] < 1.5 and last["falls"] in (0, 1)
    assert np.isfinite(last["final_goal_distance"]) and last["env_steps_per_s"] > 0
    assert out["compiles"] == [1, 1]  # both chunks: one compile
    # the ant's carry checkpoints and restores (MJX data has zero-size leaves)
    assert out["weak_leaves"] == 0  # as a restored carry
    assert out["restored_chunks"] == 2 and out["restored_rows"] == 2
    assert out["same_structure"] and out["restored_params_differ"]


def test_memory_is_estimated_before_compiling_and_too_big_runs_are_refused():
    cfg = dataclasses.replace(TINY, seeds=2)
    need = train.carry_bytes(cfg)
    # two seeds x (replay of buffer_episodes x 101 states x (obs 4 + goal 2 + z 1) floats...)
    per_seed_replay = cfg.buffer_episodes * (cfg.horizon + 1) * 7 * 4
    assert 2 * per_seed_replay < need < 2 * per_seed_replay + 50 * 2**20
    assert train.check_memory(cfg, available=10 * need) == need
    with pytest.raises(train.ConfigError, match="GiB per device"):
        train.check_memory(cfg, available=need)
    big = dataclasses.replace(cfg, buffer_episodes=10**7)
    assert train.carry_bytes(big) > 10 * 2**30  # shapes only: nothing was allocated


def test_non_finite_parameters_stop_the_run_and_keep_the_last_good_checkpoint(tmp_path,
                                                                              monkeypatch):
    """A NaN injected into seed 1's actor during the third chunk: the run stops naming the
    seed and the chunk's last step, and keeps the rows and checkpoints of the first two."""
    cfg = dataclasses.replace(TINY, seeds=2, steps=4 * TINY.steps_per_chunk, out=str(tmp_path))
    real_build = train.build

    def faulty_build(c):
        init, chunk, evaluate = real_build(c)

        def chunk_with_fault(carry, first_episode):
            carry, m = chunk(carry, first_episode)
            if int(first_episode) == 2 * c.episodes_per_chunk:
                poison = lambda x: x.at[1].set(jnp.nan)  # noqa: E731
                carry = carry.replace(agent=carry.agent.replace(
                    actor_params=jax.tree.map(poison, carry.agent.actor_params)))
            return carry, m

        return init, chunk_with_fault, evaluate

    monkeypatch.setattr(train, "build", faulty_build)
    with pytest.raises(train.TrainingFault, match=r"seed 1: non-finite .*parameters.* env step "
                                                  r"1200; the last good checkpoint \(chunk 2\)"):
        train.train(cfg, progress=False)
    with open(tmp_path / "metrics.csv") as f:
        assert [int(r["step"]) for r in csv.DictReader(f)] == [400, 400, 800, 800]
    assert sorted(os.listdir(tmp_path / "checkpoints")) == ["chunk_000001", "chunk_000002"]


def test_sigkilled_run_resumes_to_the_uninterrupted_metrics(tmp_path):
    """The CLI run is killed with SIGKILL once it has checkpointed, then resumed with
    ``--resume``: its metrics.csv equals an uninterrupted run's, up to the timing columns."""
    import signal
    import subprocess
    import sys
    import time

    flags = ["--env", "point3leg", "--algo", "flat", "--preset", "quick", "--seeds", "2",
             "--steps", "4000",
             "--episodes-per-chunk", "1", "--initial-episodes", "4", "--eval-episodes", "2"]
    whole, cut = str(tmp_path / "whole"), str(tmp_path / "cut")
    cmd = [sys.executable, "-m", "flrjax.train", *flags]
    subprocess.run([*cmd, "--out", whole], check=True, capture_output=True, timeout=600)
    proc = subprocess.Popen([*cmd, "--out", cut], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    ckpts = os.path.join(cut, "checkpoints")
    deadline = time.time() + 600
    while time.time() < deadline and proc.poll() is None:  # wait for 2 checkpoints
        if os.path.isdir(ckpts) and len([d for d in os.listdir(ckpts)
                                         if d.startswith("chunk_")]) >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    with open(os.path.join(cut, "metrics.csv")) as f:
        n_before = len(list(csv.DictReader(f)))
    assert 0 < n_before < 20, "the kill came too late to test anything"
    subprocess.run([*cmd[:3], "--resume", cut], check=True, capture_output=True, timeout=600)

    def table(d):
        with open(os.path.join(d, "metrics.csv")) as f:
            return [{k: v for k, v in r.items() if k not in ("wall_time", "env_steps_per_s")}
                    for r in csv.DictReader(f)]

    assert table(cut) == table(whole) and len(table(whole)) == 20


def test_help_groups_every_flag_and_shows_the_defaults(capsys):
    with pytest.raises(SystemExit):
        train.parse_cli(["--help"])
    text = " ".join(capsys.readouterr().out.split())  # unwrapped
    grouped = [f for fields in train.FLAG_GROUPS.values() for f in fields]
    assert sorted(grouped) == sorted(train.FLAG_HELP)  # each flag in exactly one group
    for title in ("run:", "learner", "graph and DHRL", "FLR (", "PIG (", "sweeps:",
                  "checkpoints:"):
        assert title in text, title
    assert "(default flr_dhrl)" in text and "(default point3leg)" in text
    assert "(default 1)" in text and "[quick 9600, paper 1200000, fast 1920000]" in text


def test_the_main_command_trains_flr_dhrl_with_the_fast_preset_on_a_gpu(monkeypatch):
    cpu = train.parse_cli(["--env", "ant3leg", "--seeds", "5", "--out", "/tmp/never-made"])
    assert (cpu.cfg.algo, cpu.preset) == ("flr_dhrl", "quick")
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    gpu = train.parse_cli(["--env", "ant3leg", "--seeds", "5", "--out", "/tmp/never-made"])
    assert gpu.preset == "fast" and gpu.cfg == train.TrainConfig(
        env="ant3leg", seeds=5, out="/tmp/never-made", **train.PRESETS["fast"])
    assert "FLR+DHRL (flr_dhrl) on ant3leg, 5 seed(s), preset fast: 1,920,000 env steps" \
        in train.start_line(gpu)


def _bad_outs(tmp_path) -> dict[str, str]:
    """--out paths no run may write into, by the error they give."""
    (tmp_path / "a_file").write_text("mine")
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "metrics.csv").write_text("someone's numbers")
    return {str(tmp_path / "a_file"): "is a file, not a directory",
            str(tmp_path / "a_file" / "run"): "a_file is a file, not a directory",
            str(tmp_path / "foreign"): "holds metrics.csv but no config.json"}


def test_out_paths_that_cannot_take_a_run_give_one_line_errors_and_stay_untouched(
        tmp_path, capsys):
    for out, message in _bad_outs(tmp_path).items():
        with pytest.raises(SystemExit) as e:
            train.parse_cli(["--algo", "flat", "--out", out])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (out, err)
    assert (tmp_path / "a_file").read_text() == "mine"
    assert (tmp_path / "foreign" / "metrics.csv").read_text() == "someone's numbers"
    assert sorted(os.listdir(tmp_path / "foreign")) == ["metrics.csv"]


def test_fuzzed_command_lines_through_main_never_show_a_traceback(tmp_path, monkeypatch,
                                                                   capsys):
    """The whole CLI path up to training (parse, --out and --resume checks, compile cache,
    start line), with training replaced by a stub: every command line either reaches
    training with a valid config or exits with one line, code 2, and no file is changed."""
    reached = []
    monkeypatch.setattr(train, "train", lambda cfg, **kw: reached.append(cfg) or [])
    monkeypatch.setattr(train, "enable_compile_cache", lambda path: None)
    bad = _bad_outs(tmp_path)
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "config.json").write_text("{not json")
    run = tmp_path / "saved"
    train.prepare_out(dataclasses.replace(TINY, out=str(run)))  # a run with no checkpoint
    outs = [*bad, str(tmp_path / "fresh"), str(run)]
    resumes = [str(tmp_path / "nowhere"), str(tmp_path / "broken"), str(run), *bad]
    rng = np.random.default_rng(1)
    flags = ["--" + k.replace("_", "-") for k in train.FLAG_HELP] + [
        "--env", "--algo", "--seeds", "--seed", "--preset"]
    values = ["0", "-1", "1", "2", "100", "0.5", "nan", "abc", "point3leg", "nope", "flat",
              "quick", "fast"]
    before = {p: sorted(os.listdir(p)) for p in tmp_path.iterdir() if p.is_dir()}
    for i in range(150):
        argv = ["--env", "point3leg", "--algo", "flat"]
        if i % 3 == 2:
            argv = ["--resume", str(rng.choice(resumes))]
        else:
            argv += ["--out", str(rng.choice(outs))]
        for _ in range(rng.integers(0, 3)):
            argv += [str(rng.choice(flags)), str(rng.choice(values))]
        n = len(reached)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                train.main(argv)
        except SystemExit as e:
            assert e.code == 2 and len(reached) == n, argv
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and err[0].startswith("python -m flrjax.train: error:"), \
                (argv, err)
        else:
            assert len(reached) == n + 1, argv
            train.validate(reached[-1])
            capsys.readouterr()
    assert reached  # some lines were valid
    assert {p: sorted(os.listdir(p)) for p in tmp_path.iterdir() if p.is_dir()} == before
    assert (tmp_path / "a_file").read_text() == "mine"


def test_a_cli_run_ends_with_a_summary_curves_and_tensorboard_events(tmp_path, capsys):
    out = str(tmp_path / "run")
    train.main(["--env", "point3leg", "--algo", "flat", "--seeds", "2", "--steps", "800",
                "--episodes-per-chunk", "1", "--initial-episodes", "4", "--eval-episodes", "2",
                "--out", out, "--tensorboard", "--no-compile-cache"])
    text = capsys.readouterr().out
    assert text.startswith("flat TD3+HER (flat) on point3leg, 2 seed(s), preset quick")
    assert "done: 800 of 800 env steps per seed" in text and "± is the sample std" in text
    files = sorted(os.listdir(out))
    assert {"config.json", "metrics.csv", "summary.json", "curves.png", "checkpoints"} <= \
        set(files) and any(f.startswith("events.out.tfevents") for f in files)
    for f in ("summary.json", "curves.png", "metrics.csv"):
        assert os.path.join(out, f) in text
    with open(os.path.join(out, "summary.json")) as f:
        summary = json.load(f)
    with open(os.path.join(out, "metrics.csv")) as f:
        last = [float(r["success_rate"]) for r in csv.DictReader(f) if r["step"] == "800"]
    assert summary["points"][0]["success"]["mean"] == pytest.approx(np.mean(last))
    assert summary["env_steps_per_seed"] == 800 and summary["seeds"] == 2
    with open(os.path.join(out, "config.json")) as f:
        config = json.load(f)
    assert set(config["git"]) == {"commit", "clean"} and config["command"]


def test_importing_flrjax_prints_nothing():
    """MJX prints "Failed to import warp" twice when NVIDIA Warp is absent; flrjax drops it."""
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-c", "import flrjax.train"], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0 and res.stdout == "" and "warp" not in res.stderr, res
