"""The host loop on the point-mass maze: learning, reproducibility, no recompilation,
sharding over devices, the memory check, the stop on non-finite values and the clean stop on
SIGINT and SIGTERM."""

import csv
import dataclasses
import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import algos, config, distributed, runner, stops
from flrjax.metric_names import TIMES
from tests.tiny import QUICK, TINY


def test_flat_learner_reaches_nearby_goals_for_two_vmapped_seeds():
    """Chunks of two episode rounds: the first chunk is the random-action phase (no update),
    so its evaluation is the untrained policy's; two chunks of learning later both seeds
    reach the nearby goals the untrained policy did not."""
    cfg = dataclasses.replace(QUICK, seeds=2, steps=2400, episodes_per_chunk=2)
    assert cfg.episodes_per_chunk * cfg.num_envs == cfg.initial_episodes  # random: chunk 1
    rows = runner.train(cfg, progress=False)
    first, last = ([r for r in rows if r["step"] == step]
                   for step in (cfg.steps_per_chunk, cfg.steps))
    assert len(first) == len(last) == 2
    # deterministic policy, 10 goals drawn as in training, within 5 at the end
    assert all(r["random_goal_success"] < 0.8 for r in first), first
    for r in last:
        assert r["random_goal_success"] >= 0.8, r
        assert np.isfinite(r["critic_loss"]) and r["falls"] == 0


def test_same_seed_same_metrics_and_one_compilation(tmp_path):
    a = runner.train(dataclasses.replace(TINY, seeds=2, out=str(tmp_path / "a")), progress=False)
    b = runner.train(dataclasses.replace(TINY, seeds=2, out=str(tmp_path / "b")), progress=False)
    c = runner.train(dataclasses.replace(TINY, seeds=2, seed=1), progress=False)
    strip = [{k: v for k, v in r.items() if k not in TIMES} for r in a]
    assert strip == [{k: v for k, v in r.items() if k not in TIMES} for r in b]
    assert strip != [{k: v for k, v in r.items() if k not in TIMES} for r in c]
    assert len(a) == 2 * (TINY.steps // TINY.steps_per_chunk)
    # three runs, several chunks each: the chunk was compiled once
    _, chunk, evaluate = runner.build(dataclasses.replace(TINY, seeds=2))
    assert chunk._cache_size() == 1 and evaluate._cache_size() == 1
    with open(tmp_path / "a" / "metrics.csv") as f:
        written = list(csv.DictReader(f))
    assert len(written) == len(a) and set(written[0]) == set(runner.metric_fields(TINY))
    # each chunk's seconds split into its training and its evaluation, within the wall time
    for prev, r in zip(a[::2], a[2::2], strict=False):
        assert r["chunk_s"] > 0 and r["eval_s"] > 0
        assert r["chunk_s"] + r["eval_s"] <= r["wall_time"] - prev["wall_time"]
    assert os.path.exists(tmp_path / "a" / "config.json")


def test_runs_share_programs_unless_they_differ_in_what_shapes_them():
    """Seed, length, output, checkpoints and the learners' numbers the states carry (one value,
    or a sweep's with as many points) leave the programs' key as it is, so a launch with
    other such values loads the programs stored for it; its own numbers go in as init's
    argument. A size, a number the programs hold (FLR's alpha) or another count of points
    is another key. Nothing is traced."""
    cfg = dataclasses.replace(TINY, algo="flr_dhrl")
    key = runner._shape_key
    same = [dataclasses.replace(cfg, seed=3, out="elsewhere", steps=2 * cfg.steps,
                                checkpoint_every=0),
            cfg.replace(lr_critic=5e-4, polyak=0.9, gamma=0.95, high_lr_actor=1e-5)]
    for other in same:
        assert key(other) == key(cfg)
        assert runner.build(other)[1] is runner.build(cfg)[1]
    numbers = [jax.tree.leaves(runner.build(c)[0].hparams) for c in (cfg, same[1])]
    assert any(not np.array_equal(a, b) for a, b in zip(*numbers, strict=True))
    swept = cfg.replace(lr_critic=(1e-3, 5e-4))
    assert key(swept) == key(cfg.replace(lr_critic=(2e-3, 1e-4))) != key(cfg)
    points = [((("lr_critic", 1e-3),), (("flr_alpha", 0.0),)),
              ((("lr_critic", 5e-4),), (("flr_alpha", 0.0),))]
    assert key(cfg.replace(sweep=points[0])) == key(cfg.replace(sweep=points[1]))
    for other in (cfg.replace(hidden=32), cfg.replace(flr_alpha=0.1)):
        assert key(other) != key(cfg)


def test_progress_fn_sees_every_chunk_and_can_end_the_run(tmp_path):
    cfg = dataclasses.replace(TINY, steps=3 * TINY.steps_per_chunk, out=str(tmp_path / "run"))
    seen = []

    def progress(step, rows):
        seen.append((step, len(rows)))
        return step >= 2 * TINY.steps_per_chunk  # e.g. a target success reached

    rows = runner.train(cfg, progress=False, progress_fn=progress)
    n = TINY.steps_per_chunk
    assert seen == [(n, cfg.seeds), (2 * n, cfg.seeds)]
    assert rows[-1]["step"] == 2 * n and len(rows) == 2 * cfg.seeds
    assert sorted(os.listdir(os.path.join(cfg.out, "checkpoints"))) == [
        "chunk_000001", "chunk_000002"]  # checkpoint_every=1, as without the hook


# FLR+DHRL on the point mass, 2 seeds: its first graph after a chunk, V on the reaching
# transitions 8 at a time
FLR_DHRL = TINY.replace(env="point4leg", algo="flr_dhrl", seeds=2, graph_start_steps=400,
                        graph_every_steps=800, max_landmarks=8, landmark_sample=64,
                        flr_candidates=4, flr_value_chunk=8)


def test_flr_dhrl_runs_end_to_end_and_logs_the_reward_gap(tmp_path):
    cfg = dataclasses.replace(FLR_DHRL, steps=1200, out=str(tmp_path))
    rows = runner.train(cfg, progress=False)
    assert [r["step"] for r in rows] == [400, 400, 800, 800, 1200, 1200]
    last = rows[-1]
    assert last["graph_nodes"] >= 1 and np.isfinite(last["critic_loss"])
    # the point mass never falls: every reaching transition is upright, the gap has no data
    assert last["reach_fallen_frac"] == 0.0 and np.isnan(last["reward_gap"])
    assert -1.0 <= last["reach_reward_upright"] <= 0.0
    assert 0.0 < last["reach_frac"] < 1.0  # some HER transitions reach their subgoal, not all
    with open(tmp_path / "metrics.csv") as f:
        assert set(next(csv.DictReader(f))) == set(runner.metric_fields(cfg))


def test_flr_on_reaching_transitions_only_trains_like_flr_on_all(tmp_path):
    """V evaluated on the reaching transitions only, 8 at a time (batch 32), trains as V on
    every transition (--flr-value-chunk 0) does: the rewards are the same, so are the metrics
    (up to float). The run with 8 reuses the previous test's programs."""
    cfg = dataclasses.replace(FLR_DHRL, steps=800)
    runs = {chunk: runner.train(cfg.replace(flr_value_chunk=chunk,
                                                    out=str(tmp_path / f"{chunk}")),
                                progress=False) for chunk in (0, 8)}
    assert 0.0 < runs[8][-1]["reach_frac"] < 1.0
    for k in ("critic_loss", "q", "reach_frac", "reach_reward_upright", "final_goal_distance",
              "high_q"):
        np.testing.assert_allclose([r[k] for r in runs[8]], [r[k] for r in runs[0]],
                                   rtol=1e-4, atol=1e-5, err_msg=k)


def _on_cpu_devices(n: int, script: str, *args: str) -> dict:
    """Run ``script`` in a fresh Python with ``n`` forced CPU devices (set before JAX starts;
    the session's XLA flags kept) and return the JSON of its last output line."""
    import subprocess
    import sys

    env = {**os.environ, "XLA_FLAGS": os.environ.get("XLA_FLAGS", "")
           + f" --xla_force_host_platform_device_count={n}"}
    res = subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])

SHARDED_SCRIPT = """
import dataclasses, json
import jax, jax.numpy as jnp, numpy as np
from flrjax import config, presets, run_axis, runner
assert jax.device_count() == 4, jax.devices()
cfg = config.TrainConfig(env="point3leg", algo="flat", **{**presets.PRESETS["quick"], "steps": 800,
                         "episodes_per_chunk": 1, "initial_episodes": 4, "eval_episodes": 2,
                         "seeds": 4})
def params(agent):  # [seeds, all float parameters]
    return np.concatenate([np.asarray(x, np.float64).reshape(cfg.seeds, -1)
                           for x in jax.tree.leaves(agent)
                           if jnp.issubdtype(x.dtype, jnp.floating)], 1)
before, after, random_round, split, compiles = {}, {}, {}, {}, {}
for devices in (4, 1):
    c = dataclasses.replace(cfg, devices=devices)
    init, chunk, _ = runner.build(c)
    carry = runner.init_carry(c, init, jax.random.PRNGKey(0))
    split[devices] = all(x.sharding.is_equivalent_to(run_axis.shard_seeds(c), x.ndim)
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
                  "auto": runner.num_devices(cfg), "split_along_seeds": all(split.values()),
                  "chunk_compiles": list(compiles.values())}))
"""


def _avals(tree) -> dict[str, tuple]:
    """Shape, dtype and weak type of each leaf, by path: what a jitted function's cache is
    keyed on."""
    return {jax.tree_util.keystr(p): (x.shape, x.dtype, x.weak_type)
            for p, x in jax.tree_util.tree_leaves_with_path(tree)}


@pytest.mark.parametrize("obs_norm", [False, True])
@pytest.mark.parametrize("algo", algos.names())
def test_carry_is_strongly_typed_and_the_chunk_keeps_its_types(algo, obs_norm):
    """Traced only. No leaf of the initial carry is weakly typed (as one made from a bare
    Python 0.0 is): a checkpoint restores every leaf strongly typed, and the chunk would
    compile again for the restored carry, and a first launch's chunk prefetched for the
    strongly typed shapes compiles again for its first call. And a chunk returns the carry
    with the types it took, or the next chunk would compile again (so init alone cannot fix a
    weak leaf). With ``obs_norm`` too: brax's running statistics."""
    init, chunk, _ = runner.build(dataclasses.replace(TINY, algo=algo, obs_norm=obs_norm))
    carry = jax.eval_shape(init, jax.ShapeDtypeStruct((1, 2), jnp.uint32))
    assert not [path for path, (_, _, weak) in _avals(carry).items() if weak]
    out, _ = jax.eval_shape(chunk, carry, jax.ShapeDtypeStruct((), jnp.int32))
    assert _avals(out) == _avals(carry)


def test_init_lowered_from_shapes_is_the_program_a_call_runs():
    """``init.lower(keys)`` (a benchmark's compile ahead, from shapes) lowers the program a
    call runs, the learner numbers placed beside the keys as a call places them: else the
    trainer's first call compiles init again."""
    init, _, _ = runner.build(TINY)
    where = runner.shard_seeds(TINY)
    keys = distributed.put(runner.run_keys(TINY, jax.random.PRNGKey(0)), where)
    ahead = init.lower(jax.ShapeDtypeStruct(keys.shape, keys.dtype, sharding=where))
    call = init.program.lower(keys, jax.tree.map(lambda x: distributed.put(x, where),
                                                 init.hparams))
    assert ahead.as_text() == call.as_text()


@pytest.mark.parametrize("deterministic", [False, True])
def test_the_programs_compile_with_the_trainers_xla_options(monkeypatch, deterministic):
    """Each of init, chunk and evaluate is compiled with ``runner.COMPILER_OPTIONS``, and with
    ``DETERMINISTIC_OPTIONS`` too for ``--deterministic``: a value XLA refuses in them makes
    every one fail (the options are read when each is jitted)."""
    bad = {"xla_gpu_command_buffer_scheduling_mode": "NOT_A_MODE"}
    monkeypatch.setattr(runner, "DETERMINISTIC_OPTIONS" if deterministic else "COMPILER_OPTIONS",
                        bad)
    runner._build.cache_clear()
    try:
        init, chunk, evaluate = runner.build(
            dataclasses.replace(TINY, seed=11, deterministic=deterministic))
        keys = jax.ShapeDtypeStruct((1, 2), jnp.uint32)
        carry = jax.eval_shape(init, keys)
        for fn, args in ((init, (keys,)), (chunk, (carry, jax.ShapeDtypeStruct((), jnp.int32))),
                         (evaluate, (carry, keys))):
            with pytest.raises(Exception, match="NOT_A_MODE"):
                fn.lower(*args).compile()
        if deterministic:  # without the flag the same run compiles
            runner.build(TINY)[0].lower(keys).compile()
    finally:
        runner._build.cache_clear()


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
    out = _on_cpu_devices(4, SHARDED_SCRIPT)
    assert out["auto"] == 4 and out["devices"] == 4  # the carry lives on all four
    # every leaf split along seeds (none replicated), so the chunk compiled once, not again
    # when its sharded output came back as input
    assert out["split_along_seeds"] and out["chunk_compiles"] == [1, 1], out
    assert out["same_buffer_after_random_round"] and out["same_params_after_random_round"], out
    assert out["nearest_unsharded"] == [0, 1, 2, 3], out
    assert min(out["own_over_move"]) > 0.5, out  # the bound below can tell sharing apart
    assert max(out["diff_over_move"]) < 0.25, out


FUSED_SPLIT_SCRIPT = """
import dataclasses, json, re
import jax, jax.numpy as jnp, numpy as np
from flrjax import runner
from tests.tiny import TINY
assert jax.device_count() == 4, jax.devices()
op = re.compile(r" (all-gather|all-reduce|all-to-all|collective-permute|reduce-scatter)")
cfg = dataclasses.replace(TINY, seeds=3, steps=320).replace(  # chunks of 160 steps
    algo="flr_dhrl", flr_alpha=0.01, value_kernel="fused", flr_precision="bfloat16",
    subgoal_test_precision="bfloat16", updates_per_step=0.25, episode_length=40)
def params(agent):  # [runs, all float parameters]
    return np.concatenate([np.asarray(x, np.float64).reshape(cfg.runs, -1)
                           for x in jax.tree.leaves(agent)
                           if jnp.issubdtype(x.dtype, jnp.floating)], 1)
before, after, kernels, collectives = {}, {}, {}, {}
for devices in (2, 1):  # 3 runs padded to 4 on 2 of the 4 devices
    c = dataclasses.replace(cfg, devices=devices)
    init, chunk, _ = runner.build(c)
    carry = runner.init_carry(c, init, jax.random.PRNGKey(0))
    lowered = chunk.lower(carry, jnp.int32(0))
    kernels[devices] = lowered.as_text().count("sdy.manual_computation")
    compiled = lowered.compile()
    collectives[devices] = op.findall(compiled.as_text())
    carry, _ = compiled(carry, jnp.int32(0))  # a random-action round: no learning
    before[devices] = params(runner.real_runs(c, carry.low))
    carry, _ = compiled(carry, jnp.int32(1))  # a round of updates, eq. 5 by the fused kernel
    after[devices] = params(runner.real_runs(c, carry.low))
move = after[1] - before[1]
norm = lambda x: np.linalg.norm(x, axis=1)
print(json.dumps({"kernels": kernels, "collectives": collectives,
                  "padded": runner.padded_runs(dataclasses.replace(cfg, devices=2)),
                  "same_before": bool(np.array_equal(before[2], before[1])),
                  "diff_over_move": (norm(after[2] - after[1]) / norm(move)).tolist(),
                  "nearest_unsharded": [int(np.argmin(norm(after[1] - a))) for a in after[2]]}))
"""


def test_the_fused_kernel_split_over_devices_trains_as_on_one():
    """The fused kernel (Pallas's interpreter on CPU) in a program split over 2 devices: XLA
    cannot partition a Pallas call, so each call is a ``shard_map`` on each device's own runs
    (3 runs padded to 4), with no cross-device collective in the compiled chunk, and the runs
    learn as on one device, to the rounding bound of
    :func:`test_seeds_sharded_over_four_devices_train_as_unsharded`. A one-device program has
    no ``shard_map``."""
    out = _on_cpu_devices(4, FUSED_SPLIT_SCRIPT)
    assert out["padded"] == 4 and out["kernels"]["1"] == 0 and out["kernels"]["2"] > 0, out
    assert out["collectives"]["2"] == [], out
    assert out["same_before"], out
    assert out["nearest_unsharded"] == [0, 1, 2], out
    assert max(out["diff_over_move"]) < 0.25, out


PADDED_SCRIPT = """
import csv, dataclasses, json, os, sys
import jax, jax.numpy as jnp, numpy as np
from flrjax import cli, run_axis, runner
from flrjax.metric_names import TIMES
from tests.tiny import TINY
assert jax.device_count() == 4, jax.devices()
root = sys.argv[1]
cfg = dataclasses.replace(TINY, seeds=5, steps=2 * TINY.steps_per_chunk).replace(
    lr_critic=(1e-3, 3e-4))
flags = ["--env", "point3leg", "--algo", "flat", "--preset", "quick", "--seeds", "5",
         "--steps", str(cfg.steps), "--episodes-per-chunk", "1", "--initial-episodes", "4",
         "--eval-episodes", "2", "--hidden", "16", "--batch-size", "32",
         "--lr-critic", "1e-3,3e-4", "--no-compile-cache"]
def metrics(out):
    with open(os.path.join(out, "metrics.csv")) as f:
        return [{k: v for k, v in r.items() if k not in TIMES}
                for r in csv.DictReader(f)]
for name, devices in (("padded", []), ("one", ["--devices", "1"])):
    cli.main([*flags, *devices, "--out", os.path.join(root, name)])
# stopped after a chunk, then resumed with the other padding (12 runs -> 10, and 10 -> 12)
for name, first, then in (("to_one", None, 1), ("to_four", 1, None)):
    c = dataclasses.replace(cfg, devices=first, out=os.path.join(root, name))
    runner.train(c, progress=False, max_chunks=1)
    cli.main(["--resume", c.out, *(["--devices", str(then)] if then else [])])
summary = {n: json.load(open(os.path.join(root, n, "summary.json")))["points"]
           for n in ("padded", "one")}
# the stop on non-finite values: a padding run's parameters alone do not stop the run
real_finite = runner.params_finite
faults = {}
for bad in (11, 9):
    runner.params_finite = lambda algo, carry, bad=bad: jnp.arange(12) != bad
    try:
        runner.train(dataclasses.replace(cfg, steps=TINY.steps), progress=False)
        faults[bad] = None
    except runner.TrainingFault as e:
        faults[bad] = str(e)
runner.params_finite = real_finite
print(json.dumps({
    "devices": runner.num_devices(cfg), "padded": runner.padded_runs(cfg),
    "keys": np.asarray(run_axis.run_keys(cfg, jax.random.PRNGKey(0))).tolist(),
    "keys_one": np.asarray(run_axis.run_keys(dataclasses.replace(cfg, devices=1),
                                           jax.random.PRNGKey(0))).tolist(),
    "bytes": [runner.carry_bytes(dataclasses.replace(cfg, devices=d)) for d in (None, 1)],
    "metrics": {n: metrics(os.path.join(root, n)) for n in ("padded", "one", "to_one",
                                                              "to_four")},
    "summary": summary, "faults": faults}))
"""

#: Columns a padded run's rows match exactly: the labels, and the counts and rates of
#: discrete events (a rounding difference would have to cross a threshold to change them).
EXACT = ("step", "seed", "lr_critic", "success_rate", "random_goal_success", "train_success",
         "falls", "physics_resets", "reward")


def _assert_rows_match(rows, want, rtol):
    """Same rows in the same order: :data:`EXACT` columns equal, the others to ``rtol``."""
    assert len(rows) == len(want)
    for r, w in zip(rows, want, strict=True):
        assert r.keys() == w.keys()
        for k in r:
            if k in EXACT:
                assert r[k] == w[k], (k, r, w)
            else:
                np.testing.assert_allclose(float(r[k]), float(w[k]), rtol=rtol, err_msg=k)


def test_runs_padded_over_four_devices_train_as_on_one(tmp_path):
    """5 seeds x 2 sweep points (10 runs) on 4 devices: padded to 12 (3 a device), each
    padding run with its own key and the last run's values; the CLI's metrics.csv and
    summary.json hold the 10 runs as the unsharded run (``--devices 1``) does, to float
    rounding; a run stopped after a chunk resumes over another padding (12 -> 10, 10 -> 12)
    to the same rows; the carry's bytes count the padding; a padding run's non-finite
    parameters do not stop the run, a real run's do. In a fresh process: the forced CPU
    device count is set before JAX starts.

    Why a tolerance: both programs do the same float32 operations on each run, but XLA lays
    them out for 3 runs a device in one and 10 in the other, so some of them (reductions,
    vectorised transcendental functions) round otherwise, by float32's unit roundoff u =
    2^-24 (6e-8) relative. Such a difference travels, and may grow by a factor of at most
    the number of dependent operations it passes, through one chunk of a few hundred updates
    and an evaluation episode of 100 steps, a few thousand operations: ``rtol = 1e-4`` (about
    1700 u). It is far below what a misplaced run would change: seeds differ from each other
    by far more than that, which the test checks on the baseline. Discrete counts and rates
    (:data:`EXACT`) are equal."""
    out = _on_cpu_devices(4, PADDED_SCRIPT, str(tmp_path))
    assert out["devices"] == 4 and out["padded"] == 12
    keys = out["keys"]
    assert keys[:10] == out["keys_one"] and len(keys) == 12  # the real runs' keys unchanged
    assert len({tuple(k) for k in keys[10:]} | {tuple(k) for k in keys[:10]}) == 7  # 5 + 2
    padded, one = out["bytes"]
    assert padded * 10 == one * 12
    rtol = 1e-4
    m = out["metrics"]
    one = m["one"]
    assert [(r["step"], r["seed"], r["lr_critic"]) for r in one] == [
        (str(step), str(s), lr) for step in (400, 800) for lr in ("0.001", "0.0003")
        for s in range(5)]
    for name in ("padded", "to_one", "to_four"):
        _assert_rows_match(m[name], one, rtol)
    # the tolerance tells runs apart: every other run of the baseline differs by more
    last = one[10:]
    for i, r in enumerate(last):
        for j, w in enumerate(last):
            if i != j:
                assert any(k not in EXACT and not np.isclose(float(r[k]), float(w[k]),
                                                             rtol=100 * rtol)
                           for k in r if r[k] != "nan"), (i, j)
    assert [p["name"] for p in out["summary"]["padded"]] == [
        p["name"] for p in out["summary"]["one"]]
    for p, w in zip(out["summary"]["padded"], out["summary"]["one"], strict=True):
        assert p["success"] == w["success"] and p["falls_total"] == w["falls_total"]
    assert out["faults"]["11"] is None
    assert out["faults"]["9"].startswith("seed 4, lr_critic 0.0003: non-finite parameters")


COLLECTIVES_SCRIPT = """
import dataclasses, json, re
import jax, jax.numpy as jnp
from flrjax import runner
from tests.tiny import TINY
assert jax.device_count() == 4, jax.devices()
op = re.compile(r" (all-gather|all-reduce|all-to-all|collective-permute|reduce-scatter)")
found = {}
ant = dict(env="ant3leg", algo="dhrl", episode_length=40, subgoal_freq=20)
flr = dict(algo="flr_dhrl", flr_alpha=(0.0, 0.01))
for name, seeds, kw in (("flr_dhrl 4 runs", 2, flr), ("flr_dhrl 6 runs", 3, flr),  # 6: padded
                        ("ant dhrl 4 runs", 4, ant)):
    cfg = dataclasses.replace(TINY, seeds=seeds).replace(**kw)
    init, chunk, _ = runner.build(cfg)
    carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
    hlo = chunk.lower(carry, jnp.int32(0)).compile().as_text()
    found[name] = [(m.group(1), line.split(" = ")[1].split(" ")[0], "/physics/" in line
                    and line.split('op_name="')[1].split('"')[0].endswith("/solve/while"))
                   for line in hlo.splitlines() for m in op.finditer(line)]
print(json.dumps(found))
"""


def test_a_program_split_over_devices_moves_nothing_between_them():
    """The runs are independent, so the compiled chunk of a program split over 4 devices has
    no cross-device collective: FLR's alpha = 0 runs, which skip eq. 5's values on one
    device by gathering the other runs, compute them too when split (else every update
    would gather the networks across devices). Checked with the runs a multiple of the
    devices and padded (the fused kernel's split: the next test). The ant's one exception:
    MJX's constraint solver is a while loop, which, vmapped, runs until every run's solver
    has converged, so XLA all-reduces its boolean condition across the devices in each
    solver iteration; nothing else moves."""
    found = _on_cpu_devices(4, COLLECTIVES_SCRIPT)
    assert found["flr_dhrl 4 runs"] == found["flr_dhrl 6 runs"] == []
    assert found["ant dhrl 4 runs"] and all(
        c == ["all-reduce", "pred[]", True] for c in found["ant dhrl 4 runs"])


TRIPOD_SCRIPT = """
import json, sys
import jax, numpy as np
from flrjax import checkpoint, config, runner
cfg = config.make(dict(env="ant3leg", algo="flr_dhrl", seeds=1, num_envs=1, steps=80,
                         episodes_per_chunk=1, episode_length=40, subgoal_freq=20,
                         batch_size=16, hidden=16, buffer_episodes=4, initial_episodes=1,
                         eval_episodes=1, graph_start_steps=40, graph_every_steps=40,
                         max_landmarks=4, landmark_sample=16, flr_candidates=2, out=sys.argv[1]))
rows = runner.train(cfg, progress=False)
init, chunk, evaluate = runner.build(cfg)
template = init(jax.random.split(jax.random.PRNGKey(0), 1))
shapes = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding),
                      template)  # as a resume restores: MJX's zero-size leaves made empty
done, carry, saved_rows = checkpoint.restore(cfg, shapes, runner.metric_fields(cfg))
kernel = lambda c: c.low.actor.params["params"]["MLP_0"]["TorchDense_0"]["kernel"]
print(json.dumps({
    "steps": [r["step"] for r in rows],
    "last": {k: float(rows[-1][k]) for k in ("graph_nodes", "critic_loss", "final_torso_z",
                                               "falls", "final_goal_distance",
                                               "env_steps_per_s")},
    "compiles": [chunk._cache_size(), evaluate._cache_size()],
    "weak_leaves": sum(x.weak_type for x in jax.tree.leaves(template)),
    "restored_chunks": done, "restored_rows": len(saved_rows),
    "same_structure": jax.tree.structure(carry) == jax.tree.structure(template),
    "empty_leaves": [x.shape for x in jax.tree.leaves(carry) if x.size == 0],
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
    assert out["same_structure"] and out["restored_params_differ"] and out["empty_leaves"]


def test_memory_is_estimated_before_compiling_and_too_big_runs_are_refused():
    cfg = dataclasses.replace(TINY, seeds=2)
    need = runner.carry_bytes(cfg)
    # two seeds x (replay of buffer_episodes x 101 states x (obs 4 + goal 2 + z 1) floats...)
    per_seed_replay = cfg.buffer_episodes * (cfg.horizon + 1) * 7 * 4
    assert 2 * per_seed_replay < need < 2 * per_seed_replay + 50 * 2**20
    assert runner.check_memory(cfg, available=10 * need) == need
    with pytest.raises(config.ConfigError, match="GiB per device"):
        runner.check_memory(cfg, available=need)
    big = dataclasses.replace(cfg, buffer_episodes=10**7)
    assert runner.carry_bytes(big) > 10 * 2**30  # shapes only: nothing was allocated


def test_non_finite_parameters_stop_the_run_and_keep_the_last_good_checkpoint(tmp_path,
                                                                              monkeypatch):
    """A NaN injected into seed 1's actor during the third chunk: the run stops naming the
    seed and the chunk's last step, and keeps the rows and checkpoints of the first two."""
    cfg = dataclasses.replace(TINY, seeds=2, steps=4 * TINY.steps_per_chunk, out=str(tmp_path))
    real_build = runner.build

    def faulty_build(c):
        init, chunk, evaluate = real_build(c)

        def chunk_with_fault(carry, first_episode):
            carry, m = chunk(carry, first_episode)
            if int(first_episode) == 2 * c.episodes_per_chunk:
                poison = lambda x: x.at[1].set(jnp.nan)  # noqa: E731
                actor = carry.agent.actor
                carry = carry.replace(agent=carry.agent.replace(
                    actor=actor.replace(params=jax.tree.map(poison, actor.params))))
            return carry, m

        return init, chunk_with_fault, evaluate

    runner.metric_fields(cfg)  # the columns from the real programs (cached), not the patched
    monkeypatch.setattr(runner, "build", faulty_build)
    with pytest.raises(runner.TrainingFault, match=r"seed 1: non-finite .*parameters.* env step "
                                                  r"1200; the last good checkpoint \(chunk 2\)"):
        runner.train(cfg, progress=False)
    with open(tmp_path / "metrics.csv") as f:
        assert [int(r["step"]) for r in csv.DictReader(f)] == [400, 400, 800, 800]
    assert sorted(os.listdir(tmp_path / "checkpoints")) == ["chunk_000001", "chunk_000002"]


def test_finite_check_stops_on_any_learners_metric_in_any_episode_whatever_its_name():
    """A learner's metric (low/, high/, aux/) non-finite in one episode of the chunk stops the
    run, named, whether or not its name ends in "loss"; the same NaN as a statistic does not."""
    cfg = dataclasses.replace(TINY, seeds=2)
    params_ok, finite = np.ones(cfg.runs, bool), np.ones((cfg.runs, 3), np.float32)
    for name, value in (("high/q", np.nan), ("low/q", np.inf), ("aux/rnd_loss", np.nan),
                        ("low/reward", -np.inf)):
        bad = finite.copy()
        bad[1, 2] = value  # one episode of seed 1: the mean over the others would hide a NaN
        with pytest.raises(runner.TrainingFault,
                           match=f"^seed 1: non-finite {name} in the chunk ending at env step "
                                 "400$"):
            runner._check_finite({"low/critic_loss": finite, name: bad}, params_ok, 400, 0, cfg)
        runner._check_finite({"low/critic_loss": finite, "stats/" + name.split("/")[1]: bad},
                             params_ok, 400, 0, cfg)


def test_finite_check_lets_statistics_be_nan_for_lack_of_data():
    """FLR's reward statistics are NaN in a chunk with no reaching transition (or none from a
    fallen state): not a fault."""
    cfg = dataclasses.replace(TINY, seeds=2)
    nan = np.full((cfg.runs, 3), np.nan, np.float32)
    metrics = {"low/critic_loss": np.ones((cfg.runs, 3)), "stats/reach_reward_fallen": nan,
               "stats/reward_gap": nan, "stats/reach_frac": nan}
    assert runner._check_finite(metrics, np.ones(cfg.runs, bool), 400, 0, cfg) is None


def test_metric_columns_keep_their_flat_names_and_order():
    """metrics.csv's columns from the namespaced metrics (:mod:`flrjax.metric_names`): those
    from before the namespaces, the evaluation's then the chunk's, each alphabetical."""
    assert runner.metric_fields(TINY) == (
        "step", "seed", "falls", "final_goal_distance", "final_torso_z",
        "random_goal_distance", "random_goal_success", "success_rate", "actor_loss",
        "critic_loss", "physics_resets", "q", "reward", "train_success", "wall_time",
        "env_steps_per_s", "chunk_s", "eval_s")


def test_the_progress_bar_leaves_the_first_chunks_compile_out_of_its_rate():
    import io

    bar = runner._progress(10, TINY)
    bar.fp = io.StringIO()
    bar.start_t = bar.last_print_t = bar._time() - 100.0  # 100 s of chunk, 90 of it compiling
    runner._leave_out_compile(bar, 90.0, 100.0, "tracing 1.0 s")
    bar.update(1)
    elapsed = bar.format_dict["elapsed"]
    assert 10.0 <= elapsed < 12.0  # so the rate is 1 chunk per ~10 s and 9 chunks left ~90 s
    assert "90 s of it tracing and compiling" in bar.fp.getvalue()
    assert "compiles so far: tracing 1.0 s" in bar.fp.getvalue()
    bar.close()


def test_the_first_chunks_compile_is_what_jax_compiled_not_the_calls_time(monkeypatch,
                                                                          capsys):
    """The first chunk's compile seconds are JAX's compile events, so a chunk call that
    returns only after its chunk ran (as on a GPU, where XLA's while loops read their
    condition on the host) is not counted as compiling: here the call sleeps 6 s after
    the chunk has run, against about 2 s of evaluation after it."""
    import re
    import time

    build = runner.build

    def blocking_build(cfg):
        init, chunk, evaluate = build(cfg)

        def run_then_sleep(carry, i):
            out = jax.block_until_ready(chunk(carry, i))
            time.sleep(6.0)
            return out

        run_then_sleep.eval_shape = chunk.eval_shape
        return init, run_then_sleep, evaluate

    monkeypatch.setattr(runner, "build", blocking_build)
    runner.train(dataclasses.replace(TINY, seed=11), max_chunks=1)
    line = re.search(r"first chunk: (\d+) s, (\d+) s of it tracing and compiling",
                     capsys.readouterr().err)
    assert line and int(line[1]) - int(line[2]) >= 5, line  # 6 s, less rounding


def test_a_signal_stops_train_after_its_chunk_with_a_checkpoint_and_resume_finishes(tmp_path):
    """SIGTERM during chunk 2 of 4 (sent from the hook after chunk 1): the run stops after
    chunk 2 with a checkpoint of it although ``checkpoint_every=0``, and resumes to the
    uninterrupted run's rows; without an output directory it stops the same, saying so."""
    import signal
    import threading

    cfg = dataclasses.replace(TINY, steps=4 * TINY.steps_per_chunk, checkpoint_every=0,
                              out=str(tmp_path))
    whole = runner.train(dataclasses.replace(cfg, out=None), progress=False)

    def signal_after_chunk_1(step, rows):
        if step == TINY.steps_per_chunk:
            signal.pthread_kill(threading.main_thread().ident, signal.SIGTERM)

    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(stops.Stopped, match=r"^SIGTERM: stopped after chunk 2 of 4 \(env step "
                                             r"800 of 1,600\); checkpoint in ") as e:
        runner.train(cfg, progress=False, progress_fn=signal_after_chunk_1)
    assert e.value.signum == signal.SIGTERM and e.value.chunks == 2
    assert signal.getsignal(signal.SIGTERM) == before
    assert os.listdir(tmp_path / "checkpoints") == ["chunk_000002"]
    with open(tmp_path / "metrics.csv") as f:
        assert [int(r["step"]) for r in csv.DictReader(f)] == [400, 800]
    rows = runner.train(cfg, progress=False, resume=True)
    assert [{k: v for k, v in r.items() if k not in TIMES} for r in rows] == \
        [{k: v for k, v in r.items() if k not in TIMES} for r in whole]
    with pytest.raises(stops.Stopped, match="no checkpoint: the run has no output directory"):
        runner.train(dataclasses.replace(cfg, out=None), progress=False,
                     progress_fn=signal_after_chunk_1)


# A CLI run of ten short chunks: long enough to signal it between them on a slow machine.
# Small networks and batches: the tests compare runs, they need no learning.
SIGNAL_FLAGS = ["--env", "point3leg", "--algo", "flat", "--preset", "quick", "--seeds", "2",
                "--steps", "4000", "--episodes-per-chunk", "1", "--initial-episodes", "4",
                "--eval-episodes", "2", "--hidden", "16", "--batch-size", "32"]


def _metrics(out: str) -> list[dict]:
    """metrics.csv of the run in ``out``, without the timing columns."""
    with open(os.path.join(out, "metrics.csv")) as f:
        return [{k: v for k, v in r.items() if k not in TIMES}
                for r in csv.DictReader(f)]


def _train_cli(*args: str) -> list[str]:
    import sys

    return [sys.executable, "-m", "flrjax.train", *args]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory, launch_env):
    """metrics.csv of the CLI run of :data:`SIGNAL_FLAGS`, uninterrupted."""
    import subprocess

    out = str(tmp_path_factory.mktemp("signals") / "whole")
    subprocess.run(_train_cli(*SIGNAL_FLAGS, "--out", out), check=True, capture_output=True,
                   timeout=900, env=launch_env)
    return _metrics(out)


def _started_with_a_row(out: str, env: dict[str, str], *flags: str):
    """The CLI run of :data:`SIGNAL_FLAGS` into ``out``, once its first chunk's rows are in
    metrics.csv (its signal handlers are set by then)."""
    import subprocess
    import time

    proc = subprocess.Popen(_train_cli(*SIGNAL_FLAGS, *flags, "--out", out), env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    path, deadline = os.path.join(out, "metrics.csv"), time.monotonic() + 900
    while proc.poll() is None and time.monotonic() < deadline:
        if os.path.exists(path) and len(_metrics(out)) >= 2:
            return proc
        time.sleep(0.02)
    proc.kill()
    pytest.fail(f"the run ended or took too long before its first chunk: {proc.communicate()}")


@pytest.mark.parametrize("name, code, flags", [("SIGINT", 130, ()),
                                               ("SIGTERM", 143, ("--checkpoint-every", "0"))])
def test_sigint_and_sigterm_stop_the_cli_in_one_line_and_resume_equals_a_whole_run(
        uninterrupted, launch_env, tmp_path, name, code, flags):
    import re
    import signal
    import subprocess

    out = str(tmp_path / "cut")
    proc = _started_with_a_row(out, launch_env, *flags)
    proc.send_signal(getattr(signal, name))
    output = proc.communicate(timeout=900)[0]
    assert proc.returncode == code and "Traceback" not in output, output
    lines = [line for line in output.splitlines() if "stopped" in line]
    assert len(lines) == 1, output
    stop = re.fullmatch(rf"python -m flrjax\.train: {name}: stopped after chunk (\d+) of 10 "
                        rf"\(env step [\d,]+ of 4,000\); checkpoint in {re.escape(out)}\S+ "
                        rf"\(continue: python -m flrjax\.train --resume {re.escape(out)}\)",
                        lines[0])
    assert stop, lines[0]
    chunks = int(stop[1])
    assert 1 <= chunks < 10
    ckpts = sorted(os.listdir(os.path.join(out, "checkpoints")))
    assert ckpts[-1] == f"chunk_{chunks:06d}" and (flags == () or len(ckpts) == 1)
    assert _metrics(out) == uninterrupted[:2 * chunks]  # rows up to the checkpoint only
    subprocess.run(_train_cli("--resume", out), check=True, capture_output=True, timeout=900,
                   env=launch_env)
    assert _metrics(out) == uninterrupted


def test_a_second_sigint_ends_the_cli_at_once(tmp_path, launch_env):
    """The second Ctrl-C, once the first is handled, takes SIGINT's default action: the
    process ends at once (killed by the signal), not after its chunk, and prints nothing."""
    import signal
    import time

    status = "/proc/{}/status"
    if not os.path.exists(status.format(os.getpid())):
        pytest.skip("needs /proc to see when the first signal is handled")
    proc = _started_with_a_row(str(tmp_path / "cut"), launch_env)

    def catches_sigint() -> bool:
        with open(status.format(proc.pid)) as f:
            mask = next(line for line in f if line.startswith("SigCgt:")).split()[1]
        return bool(int(mask, 16) >> (signal.SIGINT - 1) & 1)

    proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + 900
    while proc.poll() is None and catches_sigint() and time.monotonic() < deadline:
        time.sleep(0.005)
    assert proc.poll() is None, "the run ended before the second signal could be sent"
    proc.send_signal(signal.SIGINT)
    output = proc.communicate(timeout=60)[0]
    assert proc.returncode == -signal.SIGINT and "Traceback" not in output, output
    assert "stopped" not in output
