"""Tests for flrjax.launch_cache: the trainer's programs stored by one launch and run by the
next without tracing them again."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax import checkpoint, launch_cache, runner
from flrjax.algos import registry
from flrjax.metric_names import TIMES
from tests.tiny import TINY


def _placed(tree) -> list[tuple]:
    """Each leaf's shape, dtype and placement."""
    return [(x.shape, x.dtype, x.sharding) for x in jax.tree.leaves(tree)]


def _one_chunk(programs) -> list[np.ndarray]:
    init, chunk, _ = programs
    init = init.bind(runner._hparams(TINY))
    carry = runner.init_carry(TINY, init, jax.random.PRNGKey(TINY.seed))
    assert _placed(runner.carry_shapes(TINY, init)) == _placed(carry)  # what a resume reads into
    carry, metrics = chunk(carry, np.int32(0))
    return [np.asarray(x) for x in jax.tree.leaves((carry, metrics))]


def test_a_second_launch_runs_the_stored_programs_without_tracing_them(tmp_path, monkeypatch):
    """The first build exports init, chunk and evaluation into the store; a second one (a new
    launch: nothing cached in memory) loads them and runs the same numbers while tracing the
    algorithm would fail. Another flrjax source is another key: exported again."""
    monkeypatch.setenv(launch_cache.SWITCH, "1")
    build = runner._build.__wrapped__  # uncached: each call is a fresh launch's build
    shape = runner._shape_key(TINY)
    monkeypatch.setattr(launch_cache, "_dir", None)
    plain = _one_chunk(build(shape))
    launch_cache.enable(str(tmp_path))
    first = build(shape)
    assert all(isinstance(p, launch_cache.Stored) for p in (first[0].program, *first[1:]))
    assert len(list(tmp_path.glob("*.bin"))) == 3
    stored = _one_chunk(first)

    def no_trace(*args, **kwargs):
        raise AssertionError("traced again")

    monkeypatch.setitem(registry._METHODS, TINY.algo, dataclasses.replace(
        registry.get(TINY.algo), train_episode=no_trace))
    second = _one_chunk(build(shape))
    for a, b, c in zip(plain, stored, second, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(b, c)
    monkeypatch.setattr(launch_cache, "source_hash", lambda: "another source")
    with pytest.warns(UserWarning, match="chunk cannot be stored"):
        _, chunk, _ = build(shape)
    assert not isinstance(chunk, launch_cache.Stored)


def test_the_trainer_runs_on_stored_programs(tmp_path, monkeypatch):
    """Two launches of one run with the store on, the second on the first's stored programs
    (everything the trainer does with them: the memory check's shapes, metric names, chunks,
    evaluation), giving the same metrics as a run without the store."""
    monkeypatch.setenv(launch_cache.SWITCH, "1")
    cfg = dataclasses.replace(TINY, seed=7)
    rows = []
    for store in (None, str(tmp_path / "store"), str(tmp_path / "store")):
        monkeypatch.setattr(launch_cache, "_dir", store)
        runner._build.cache_clear()
        runner._metric_fields.cache_clear()
        rows.append([{k: v for k, v in r.items() if k not in TIMES}
                     for r in runner.train(cfg, progress=False)])
    runner._build.cache_clear()
    runner._metric_fields.cache_clear()
    assert len(list((tmp_path / "store").glob("*.bin"))) == 3
    assert rows[0] == rows[1] == rows[2]


def test_programs_are_stored_only_where_enabled(monkeypatch, tmp_path):
    """Off unless enabled (the trainer's compilation cache turns it on beside itself), and
    off whenever FLRJAX_PROGRAM_CACHE=0."""
    monkeypatch.setattr(launch_cache, "_dir", None)
    monkeypatch.setenv(launch_cache.SWITCH, "1")
    assert launch_cache.directory() is None
    monkeypatch.setattr(runner.jax.config, "update", lambda *a: None)
    launch_cache.enable_compile_cache(str(tmp_path / "jit"))
    assert launch_cache.directory() == str(tmp_path / "jit-programs")
    monkeypatch.setenv(launch_cache.SWITCH, "0")
    assert launch_cache.directory() is None
    assert launch_cache.program("init", jax.jit(lambda x: x), (np.zeros(2),), "tag") is None
    monkeypatch.delenv(launch_cache.SWITCH)
    launch_cache.enable_compile_cache(None)
    assert launch_cache.directory() is None


def _ant_chunk_key() -> str:
    """The key of the tripod's chunk program (MJX's state, whose static fields print with
    memory addresses) for a tiny config: traced, nothing compiled."""
    cfg = runner._shape_key(dataclasses.replace(TINY, env="ant3leg", num_envs=2))
    init = runner._build.__wrapped__(cfg)[0].bind(runner._hparams(cfg))
    keys = jax.ShapeDtypeStruct((cfg.runs, 2), np.uint32)
    args = (init.eval_shape(keys), jax.ShapeDtypeStruct((), np.int32))
    return launch_cache.key("chunk", repr(cfg), args)


def test_a_programs_key_is_the_same_in_another_process():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    other = subprocess.run(
        [sys.executable, "-c", "from tests.test_launch_cache import _ant_chunk_key; "
         "print(_ant_chunk_key())"], cwd=root, capture_output=True, text=True, check=True)
    assert other.stdout.split()[-1] == _ant_chunk_key()


def test_the_store_keeps_its_size_by_deleting_the_least_recently_used(tmp_path, monkeypatch):
    """Past the limit the programs used least recently go (a load counts as a use), never the
    one just stored."""
    for i, name in enumerate(("a", "b", "c")):
        path = tmp_path / f"{name}.bin"
        path.write_bytes(b"x" * 100)
        os.utime(path, (1000 + i, 1000 + i))
    (tmp_path / "notes.txt").write_bytes(b"y" * 1000)  # not a program: left alone
    assert launch_cache.prune(str(tmp_path), 250, keep=str(tmp_path / "a.bin")) == [
        str(tmp_path / "b.bin")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "c.bin", "notes.txt"]

    monkeypatch.setenv(launch_cache.SWITCH, "1")
    monkeypatch.setattr(launch_cache, "_dir", str(tmp_path / "store"))
    monkeypatch.setattr(launch_cache, "MAX_BYTES", 1)  # any second program is one too many
    arg = (jax.ShapeDtypeStruct((3,), np.float32),)
    first = launch_cache.program("f", jax.jit(lambda x: x + 1), arg, "t")
    stored = list((tmp_path / "store").glob("*.bin"))
    assert isinstance(first, launch_cache.Stored) and len(stored) == 1
    os.utime(stored[0], (1, 1))
    launch_cache.program("f", jax.jit(lambda x: x + 1), arg, "t")  # loaded: touched
    assert os.path.getmtime(stored[0]) > 1
    launch_cache.program("g", jax.jit(lambda x: x * 2), arg, "t")  # stored: f's goes
    assert [p.name for p in (tmp_path / "store").glob("*.bin")] != [stored[0].name]
    assert len(list((tmp_path / "store").glob("*.bin"))) == 1
    # a stored program compiles with the options it was given, loaded or just exported
    bad = {"xla_gpu_command_buffer_scheduling_mode": "NOT_A_MODE"}
    for _ in range(2):
        stored = launch_cache.program("h", jax.jit(lambda x: x - 1), arg, "t",
                                      compiler_options=bad)
        with pytest.raises(Exception, match="NOT_A_MODE"):
            stored(np.zeros(3, np.float32))


def test_another_learner_number_and_a_resume_run_on_the_stored_programs(tmp_path, monkeypatch):
    """A launch with another critic learning rate (a number the states carry, so not in the
    programs' key) and a resume both run the programs a first launch stored, tracing nothing
    (the resume's checkpoint checksum neither), and that learning rate gives the metrics of a
    run on its own programs."""
    monkeypatch.setenv(launch_cache.SWITCH, "1")
    cfg = dataclasses.replace(TINY, steps=2 * TINY.steps_per_chunk, out=str(tmp_path / "run"))
    other = dataclasses.replace(cfg, lr_critic=2 * cfg.lr_critic, out=None)
    store = str(tmp_path / "store")

    def launch(directory, run, **kwargs):  # a new launch: nothing cached in memory
        monkeypatch.setattr(launch_cache, "_dir", directory)
        runner._build.cache_clear()
        runner._metric_fields.cache_clear()
        checkpoint._fold_program.cache_clear()
        return [{k: v for k, v in r.items() if k not in TIMES}
                for r in runner.train(run, progress=False, **kwargs)]

    with monkeypatch.context() as m:  # its programs traced with its own numbers in them
        m.setattr(runner, "_shape_key", lambda c: dataclasses.replace(
            c, out=None, seed=0, steps=c.steps_per_chunk))
        own = launch(None, other)
    first = launch(store, cfg, max_chunks=1)

    def no_trace(*args, **kwargs):
        raise AssertionError("traced again")

    monkeypatch.setitem(registry._METHODS, TINY.algo, dataclasses.replace(
        registry.get(TINY.algo), init=no_trace, train_episode=no_trace, evaluate=no_trace))
    monkeypatch.setattr(checkpoint, "_leaf_checksum", no_trace)
    assert launch(store, other) == own
    resumed = launch(store, cfg, resume=True)
    runner._build.cache_clear()
    runner._metric_fields.cache_clear()
    assert resumed[:1] == first and len(resumed) == 2
    assert len(list((tmp_path / "store").glob("*.bin"))) == 4  # init, chunk, evaluate, checksum


SPLIT_SCRIPT = """
import dataclasses, json, os, sys
import jax
from flrjax import checkpoint, launch_cache, runner
from flrjax.algos import registry
from flrjax.metric_names import TIMES
from tests.tiny import TINY
assert jax.device_count() == 4, jax.devices()
cfg = dataclasses.replace(TINY, seeds=3, seed=7)  # 3 runs, padded to 4 on 4 devices

def launch(store, out):  # each with a checkpoint, whose checksum is stored too
    launch_cache.enable(store)
    runner._build.cache_clear()
    runner._metric_fields.cache_clear()
    checkpoint._fold_program.cache_clear()
    run = dataclasses.replace(cfg, out=os.path.join(sys.argv[1], "..", out))
    rows = runner.train(run, progress=False)
    return [{k: v for k, v in r.items() if k not in TIMES} for r in rows]

plain = launch(None, "plain")
first = launch(sys.argv[1], "first")
files = sorted(os.listdir(sys.argv[1]))

def no_trace(*args, **kwargs):
    raise AssertionError("traced again")

registry._METHODS[cfg.algo] = dataclasses.replace(registry.get(cfg.algo),
                                                  train_episode=no_trace)
second = launch(sys.argv[1], "second")
init = runner.build(cfg)[0]
kinds = [type(p).__name__ for p in (init.program, *runner.build(cfg)[1:])]
placed = lambda t: [(x.shape, x.dtype, x.sharding) for x in jax.tree.leaves(t)]
carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
print(json.dumps({"plain_first": plain == first, "first_second": first == second,
                  "files": len(files), "after": len(os.listdir(sys.argv[1])), "kinds": kinds,
                  "rows": len(plain),
                  "resume_shapes": placed(runner.carry_shapes(cfg, init)) == placed(carry)}))
"""


def test_a_program_split_over_devices_is_stored_and_run_without_tracing(tmp_path):
    """3 runs padded to 4 on 4 devices: the first launch with the store on exports the three
    programs and its checkpoint's checksum with their shardings, the second runs them while
    tracing the algorithm would fail, both writing the rows of a launch without the store. In
    a fresh process: the forced CPU device count is set before JAX starts."""
    env = {**os.environ, "XLA_FLAGS": os.environ.get("XLA_FLAGS", "")
           + " --xla_force_host_platform_device_count=4", launch_cache.SWITCH: "1"}
    res = subprocess.run([sys.executable, "-c", SPLIT_SCRIPT, str(tmp_path / "store")],
                         env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out == {"plain_first": True, "first_second": True, "files": 4, "after": 4,
                   "kinds": ["Stored"] * 3, "rows": 3, "resume_shapes": True}


def test_the_compile_log_counts_what_jax_traces_and_compiles_inside_its_block():
    """A new program inside the block is traced, lowered and compiled (a miss of the session's
    compilation cache, tests/conftest.py); the same program after JAX's memory caches are
    cleared comes from the compilation cache; nothing is counted after the block."""
    salt = float(time.time_ns() % 10**6)  # a program no earlier session has cached
    min_secs = jax.config.jax_persistent_cache_min_compile_time_secs
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    try:
        def f(x):
            return jnp.sin(x) * salt + jnp.cos(x)

        x = np.arange(7.0, dtype=np.float32)
        with launch_cache.compile_log() as log:
            jax.jit(f)(x).block_until_ready()
            first = dict(log.programs)
            jax.clear_caches()  # as in a new process: only the compilation cache has it now
            jax.jit(f)(x).block_until_ready()
        jax.jit(lambda x: x + salt + 1.0)(x).block_until_ready()
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", min_secs)
    assert all(log.seconds[k] > 0 for k in ("tracing", "lowering", "compiling or loading"))
    assert first == {"from the compilation cache": 0, "compiled": 1}
    assert log.programs == {"from the compilation cache": 1, "compiled": 1}
    assert 0 < log.cache_read < log.seconds["compiling or loading"]  # the read is a part
    assert log.summary().endswith(f"({log.cache_read:.1f} s of it reading the compilation "
                                  "cache); programs: 1 from the compilation cache, 1 compiled")


def test_a_prefetched_program_is_compiled_before_its_first_call_and_only_then(tmp_path,
                                                                            monkeypatch):
    """prefetch compiles the program in the background, without a call; the call then runs
    that executable (no compile of its own) with its argument donated, giving what the
    function gives."""
    monkeypatch.setenv(launch_cache.SWITCH, "1")
    monkeypatch.setattr(launch_cache, "_dir", None)
    launch_cache.enable(str(tmp_path))
    salt = float(time.time_ns() % 10**6)  # a program no earlier session has cached

    def f(tree, k):
        return {"y": jnp.sin(tree["x"] * salt) + k, "n": tree["n"] + 1}

    args = ({"x": jax.ShapeDtypeStruct((5,), jnp.float32),
             "n": jax.ShapeDtypeStruct((), jnp.int32)}, jax.ShapeDtypeStruct((), jnp.int32))
    stored = launch_cache.program("f", f, args, tag="prefetch", donate_argnums=(0,))
    x = np.arange(5.0, dtype=np.float32)
    call = ({"x": jax.device_put(x), "n": jax.device_put(np.int32(2))},
            jax.device_put(np.int32(3)))
    compiles = []

    def count(event: str, secs: float, **_) -> None:
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(secs)

    jax.monitoring.register_event_duration_secs_listener(count)
    try:
        stored.prefetch(*args)
        deadline = time.monotonic() + 120
        while not compiles and time.monotonic() < deadline:
            time.sleep(0.01)
        prefetched = len(compiles)
        got = stored(*call)
    finally:
        jax.monitoring.unregister_event_duration_listener(count)
    assert prefetched == 1 and len(compiles) == 1
    want = f({"x": x, "n": np.int32(2)}, np.int32(3))
    np.testing.assert_allclose(got["y"], want["y"], rtol=1e-5)
    assert int(got["n"]) == 3


def test_the_compile_log_counts_the_seconds_inside_a_window():
    """A stage JAX reports as it ends counts from its start; a window takes only its overlap
    (a chunk's line leaves out what a background load did before the chunk began), and
    stages that ran side by side (two threads) once."""
    log = launch_cache.CompileLog()
    log.duration("/jax/core/compile/backend_compile_duration", 2.0)
    log.duration("/jax/core/compile/jaxpr_trace_duration", 0.5)  # within the first's span
    log.duration("/some/other/duration", 9.0)
    log.duration(launch_cache.CACHE_READ, 1.5)  # inside the compile's span: no span of its own
    (a, b), (c, d) = log.spans
    assert log.cache_read == 1.5 and "reading" not in log.summary()  # no program came from it
    assert (b - a, d - c, log.total()) == pytest.approx((2.0, 0.5, 2.5))
    assert a < c < b <= d
    assert log.within(a - 5, d + 5) == pytest.approx(d - a)
    assert log.within(a + 1.0, d + 5) == pytest.approx(d - a - 1.0)
    assert log.within(d + 1, d + 2) == 0.0


@pytest.mark.parametrize("launch", ["new run", "resume"])
def test_a_launch_loads_each_program_once_with_prefetch_as_without(tmp_path, monkeypatch,
                                                                   launch):
    """The trainer's prefetch of the chunk and the evaluation (and a resume's of its
    checkpoint's checksum) lowers them with the shardings their calls give (the run's mesh),
    so each program is compiled or loaded once: a launch counts as many compiles and
    compilation-cache loads as one without prefetch."""
    import shutil

    monkeypatch.setenv(launch_cache.SWITCH, "1")
    monkeypatch.setattr(launch_cache, "_dir", None)
    launch_cache.enable(str(tmp_path))
    cfg = dataclasses.replace(TINY, seeds=2, seed=int(time.time_ns() % 10**6),
                              steps=2 * TINY.steps_per_chunk)
    resume = launch == "resume"

    def programs(run: str) -> int:
        jax.clear_caches()  # as a new launch: only the stores on disk keep what it did
        runner._build.cache_clear()
        runner._metric_fields.cache_clear()
        checkpoint._fold_program.cache_clear()
        out = str(tmp_path / run) if resume else None
        if resume:  # the same checkpoint each time
            shutil.copytree(tmp_path / "first", out)
        with launch_cache.compile_log() as log:
            runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=1,
                         resume=resume)
        return sum(log.programs.values())

    min_secs = jax.config.jax_persistent_cache_min_compile_time_secs
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)  # every program
    try:
        if resume:
            runner.train(dataclasses.replace(cfg, out=str(tmp_path / "first")), progress=False,
                         max_chunks=1)
        calls, prefetch = [], launch_cache.Stored.prefetch
        monkeypatch.setattr(launch_cache.Stored, "prefetch",
                            lambda self, *args: calls.append(self) or prefetch(self, *args))
        prefetched = programs("prefetched")
        assert len(calls) == 2 + resume  # the chunk, the evaluation, the checksum
        monkeypatch.setattr(launch_cache.Stored, "prefetch", lambda self, *args: None)
        assert prefetched == programs("called") >= 3 + resume  # init, chunk, evaluation, sum
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", min_secs)
        runner._build.cache_clear()  # later tests build their own, unstored, programs
        runner._metric_fields.cache_clear()
        checkpoint._fold_program.cache_clear()
