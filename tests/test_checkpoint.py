"""Checkpoints: a run stopped (killed, out of time, SIGKILLed) resumes to the metrics of an
uninterrupted one, from an older checkpoint where the newest cannot be read."""

import csv
import dataclasses
import os
import re

import jax
import numpy as np
import pytest

from flrjax import checkpoint, cli, runner
from flrjax.config import ConfigError
from flrjax.metric_names import TIMES
from tests.tiny import TINY


def test_killed_run_resumes_to_identical_metrics(whole, tmp_path):
    cfg, _, whole = whole
    out = str(tmp_path / "cut")
    runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=2)
    # a row written after the last checkpoint (as if killed between the two) is dropped
    with open(os.path.join(out, "metrics.csv"), "a") as f:
        f.write(",".join(["999"] * len(runner.metric_fields(cfg))) + "\n")
    resumed_cfg, resume = cli.parse_cli(["--resume", out])[:2]
    assert resume and resumed_cfg == dataclasses.replace(cfg, out=out)
    # the newest checkpoint is read while the programs are built, and the restore takes it
    assert checkpoint._ahead[checkpoint.ckpt_dir(out)][0].endswith("chunk_000002")
    rows = runner.train(resumed_cfg, progress=False, resume=True)
    assert checkpoint.ckpt_dir(out) not in checkpoint._ahead
    # the restored carry has the fresh one's types: one compiled chunk for all three runs
    _, chunk, evaluate = runner.build(cfg)
    assert chunk._cache_size() == 1 and evaluate._cache_size() == 1
    assert _untimed(rows) == whole
    with open(os.path.join(out, "metrics.csv")) as f:
        assert len(list(csv.DictReader(f))) == len(whole)
    assert sorted(os.listdir(os.path.join(out, "checkpoints"))) == ["chunk_000003",
                                                                   "chunk_000004"]
    with pytest.raises(SystemExit):
        cli.parse_cli(["--resume", out, "--seeds", "3"])
    assert checkpoint.ckpt_dir(out) not in checkpoint._ahead  # nothing read for a resume refused


def test_a_stop_while_a_resume_rewrites_the_metrics_loses_no_row(whole, tmp_path, monkeypatch):
    """A resume rewrites metrics.csv with the rows up to its checkpoint as a new file put in
    its place: stopped while writing it, the run keeps its old file whole and no other."""
    cfg, _, _ = whole
    out = str(tmp_path / "cut")
    runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=2)
    with open(os.path.join(out, "metrics.csv")) as f:
        before = f.read()

    def stop(self, rows):
        raise KeyboardInterrupt

    monkeypatch.setattr(csv.DictWriter, "writerows", stop)
    with pytest.raises(KeyboardInterrupt):
        runner.train(dataclasses.replace(cfg, out=out), progress=False, resume=True)
    with open(os.path.join(out, "metrics.csv")) as f:
        assert f.read() == before and before.count("\n") == 1 + 2 * cfg.seeds
    assert not [n for n in os.listdir(out) if n.startswith("metrics.csv.")]


def test_time_limit_stops_with_a_checkpoint_and_resume_finishes(tmp_path):
    cfg = dataclasses.replace(TINY, steps=2 * TINY.steps_per_chunk, checkpoint_every=0,
                              out=str(tmp_path / "run"))
    # any limit shorter than a chunk stops after the first one, checkpointed although
    # checkpoint_every=0 keeps none otherwise
    rows = runner.train(cfg, progress=False, time_limit=1e-6)
    assert [r["step"] for r in rows] == [TINY.steps_per_chunk] * cfg.seeds
    assert os.listdir(os.path.join(cfg.out, "checkpoints")) == ["chunk_000001"]
    resumed_cfg, resume, limit = cli.parse_cli(["--resume", cfg.out, "--time-limit", "600"])[:3]
    assert resume and limit == 600.0 and resumed_cfg == cfg
    rows = runner.train(resumed_cfg, progress=False, resume=True, time_limit=limit)
    assert rows[-1]["step"] == cfg.steps and len(rows) == 2 * cfg.seeds
    for bad in ("0", "-5", "nan"):
        with pytest.raises(SystemExit):
            cli.parse_cli(["--env", "point4leg", "--time-limit", bad])


def test_a_run_with_normalised_inputs_resumes_to_the_uninterrupted_metrics(tmp_path):
    """--obs-norm: the input statistics (a count of two uint32 halves among them) are saved
    and restored with the carry, so a resumed run repeats the uninterrupted one."""
    cfg = dataclasses.replace(TINY, obs_norm=True, steps=3 * TINY.steps_per_chunk)
    whole = _untimed(runner.train(dataclasses.replace(cfg, out=str(tmp_path / "whole")),
                                  progress=False))
    out = str(tmp_path / "cut")
    runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=2)
    rows = runner.train(dataclasses.replace(cfg, out=out), progress=False, resume=True)
    assert _untimed(rows) == whole and len(whole) == 3 * cfg.seeds


def test_sigkilled_run_resumes_to_the_uninterrupted_metrics(tmp_path, launch_env):
    """The CLI run is killed with SIGKILL once it has checkpointed, then resumed with
    ``--resume``: its metrics.csv equals an uninterrupted run's, up to the timing columns."""
    import signal
    import subprocess
    import sys
    import time

    flags = ["--env", "point3leg", "--algo", "flat", "--preset", "quick", "--seeds", "2",
             "--steps", "4000",
             "--episodes-per-chunk", "1", "--initial-episodes", "4", "--eval-episodes", "2",
             "--hidden", "16", "--batch-size", "32"]  # small: it compares runs, not learning
    whole, cut = str(tmp_path / "whole"), str(tmp_path / "cut")
    cmd = [sys.executable, "-m", "flrjax.train", *flags]
    subprocess.run([*cmd, "--out", whole], check=True, capture_output=True, timeout=600,
                   env=launch_env)
    proc = subprocess.Popen([*cmd, "--out", cut], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=launch_env)
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
    subprocess.run([*cmd[:3], "--resume", cut], check=True, capture_output=True, timeout=600,
                   env=launch_env)

    assert _table(cut) == _table(whole) and len(_table(whole)) == 20


def _table(out: str) -> list[dict]:
    """metrics.csv of the run in ``out``, without the timing columns."""
    with open(os.path.join(out, "metrics.csv")) as f:
        return _untimed(csv.DictReader(f))


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """(config, output directory, rows without timings) of an uninterrupted run of four
    chunks."""
    cfg = dataclasses.replace(TINY, seeds=2, steps=4 * TINY.steps_per_chunk)
    out = str(tmp_path_factory.mktemp("whole"))
    return cfg, out, _untimed(runner.train(dataclasses.replace(cfg, out=out), progress=False))


def _untimed(rows) -> list[dict]:
    """``rows`` without the timing columns."""
    return [{k: v for k, v in r.items() if k not in TIMES} for r in rows]


def _cut_after_three_chunks(cfg, out: str) -> str:
    """``cfg`` run for three of its chunks into ``out``: checkpoints of chunks 2 and 3."""
    runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=3)
    return os.path.join(checkpoint.ckpt_dir(out), "chunk_000003")


def _damage(path: str, how: str) -> None:
    """Every file under ``path`` overwritten with random bytes or emptied."""
    for root, _, files in os.walk(path):
        for name in files:
            f = os.path.join(root, name)
            with open(f, "wb") as fh:
                fh.write(os.urandom(os.path.getsize(f)) if how == "random bytes" else b"")


@pytest.mark.parametrize("how", ["random bytes", "emptied"])
def test_resume_falls_back_past_a_damaged_newest_checkpoint(whole, tmp_path, how):
    """In-process, and through the command line, whose warning is one line."""
    import subprocess
    import sys

    cfg, whole_out, whole_rows = whole
    out = str(tmp_path / "cut")
    _damage(_cut_after_three_chunks(cfg, out), how)
    warning = (r"--resume: checkpoint \S+/chunk_000003 cannot be read \(.+\); restoring the "
               r"older chunk_000002")
    if how == "emptied":
        with pytest.warns(checkpoint.CheckpointWarning, match=f"^{warning}$"):
            rows = runner.train(dataclasses.replace(cfg, out=out), progress=False,
                                resume=True)
        assert _untimed(rows) == whole_rows
    else:
        res = subprocess.run([sys.executable, "-m", "flrjax.train", "--resume", out],
                             capture_output=True, text=True, timeout=900)
        assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
        named = [line for line in res.stderr.splitlines() if "chunk_000003" in line]
        assert len(named) == 1 and re.fullmatch(
            f"python -m flrjax.train: warning: {warning}", named[0]), res.stderr
    # chunk 3's rows, written before the damage, were dropped and trained again
    assert _table(out) == _table(whole_out)


def test_changed_array_bytes_fail_the_checkpoints_checksum(whole, tmp_path):
    """One byte of the largest array changed and the arrays written again with the checksum
    saved before: a checkpoint orbax reads without complaint (it checks its index, not the
    data), whose checksum does not match. (Bytes changed in place on disk may instead break
    orbax's own read, depending on where the arrays landed in its files.)"""
    import orbax.checkpoint as ocp

    cfg, _, whole_rows = whole
    out = str(tmp_path / "cut")
    path = _cut_after_three_chunks(cfg, out)
    with ocp.StandardCheckpointer() as ckptr:
        saved = {k: np.array(v) for k, v in ckptr.restore(path).items()}
        largest = max((k for k in saved if k != checkpoint.CHECKSUM), key=lambda k: saved[k].nbytes)
        saved[largest].view(np.uint8).reshape(-1)[saved[largest].nbytes // 2] ^= 0xFF
        ckptr.save(path, saved, force=True)
        ckptr.wait_until_finished()
    with pytest.warns(checkpoint.CheckpointWarning, match="do not match the checksum"):
        rows = runner.train(dataclasses.replace(cfg, out=out), progress=False, resume=True)
    assert _untimed(rows) == whole_rows


def test_a_checkpoint_of_other_shapes_or_dtypes_is_not_read(whole):
    """orbax would cast or reshape into the template; a mismatch must fail instead."""
    import jax.numpy as jnp

    cfg, out, _ = whole
    template = runner.init_carry(cfg, runner.build(cfg)[0], jax.random.PRNGKey(0))
    n_done, carry = checkpoint.load(out, template)
    assert n_done == 4 and jax.tree.structure(carry) == jax.tree.structure(template)
    leaves, treedef = jax.tree.flatten(template)
    i = max(range(len(leaves)), key=lambda j: leaves[j].size * (leaves[j].dtype == jnp.float32))
    for changed in (leaves[i].astype(jnp.float16), jnp.concatenate([leaves[i]] * 2)):
        other = jax.tree.unflatten(treedef, [*leaves[:i], changed, *leaves[i + 1:]])
        with pytest.raises(ConfigError, match=rf"chunk_000004: array {i} is "):
            checkpoint.load(out, other)


def test_a_resume_restores_into_a_fresh_carrys_shapes_without_computing_one(whole, tmp_path,
                                                                           monkeypatch):
    """A resume holds one carry, as a new run does, and computes none to throw away: it reads
    the checkpoint into the shapes and placement a fresh carry has (``carry_shapes``)."""
    cfg, _, whole_rows = whole
    out = str(tmp_path / "cut")
    runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=2)
    templates, load = [], checkpoint.load

    def no_init(*args):
        raise AssertionError("a resume computed a fresh carry")

    monkeypatch.setattr(runner, "init_carry", no_init)
    monkeypatch.setattr(checkpoint, "load", lambda o, t: templates.append(t) or load(o, t))
    rows = runner.train(dataclasses.replace(cfg, out=out), progress=False, resume=True)
    assert _untimed(rows) == whole_rows
    monkeypatch.undo()
    init = runner.build(cfg)[0]
    fresh = runner.init_carry(cfg, init, jax.random.PRNGKey(cfg.seed))
    for x, y in zip(jax.tree.leaves(templates[0]), jax.tree.leaves(fresh), strict=True):
        assert isinstance(x, jax.ShapeDtypeStruct)
        assert (x.shape, x.dtype, x.sharding) == (y.shape, y.dtype, y.sharding)


@pytest.mark.parametrize("newest", ["whole", "damaged"])
def test_a_read_ahead_is_the_loads_read_of_the_newest_checkpoint(whole, tmp_path, monkeypatch,
                                                                newest):
    """``read_ahead`` reads the newest checkpoint into host memory in another thread; ``load``
    takes that read, reading no file again, and places the carry as a plain load does. A
    read ahead that failed falls back to the older checkpoint, as a plain load does."""
    import threading

    cfg, _, _ = whole
    out = str(tmp_path / "cut")
    path = _cut_after_three_chunks(cfg, out)
    if newest == "damaged":
        _damage(path, "random bytes")
    shapes = runner.carry_shapes(cfg, runner.build(cfg)[0])
    plain = checkpoint.load(out, shapes)
    reads, metadata = [], checkpoint._metadata  # every read begins with the metadata
    monkeypatch.setattr(checkpoint, "_metadata", lambda p: reads.append(
        (os.path.basename(p), threading.current_thread() is threading.main_thread()))
        or metadata(p))
    checkpoint.read_ahead(out)
    if newest == "whole":
        n_done, carry = checkpoint.load(out, shapes)
        assert reads == [("chunk_000003", False)]
    else:
        with pytest.warns(checkpoint.CheckpointWarning, match="restoring the older"):
            n_done, carry = checkpoint.load(out, shapes)
        assert reads == [("chunk_000003", False), ("chunk_000002", True)]
    assert checkpoint.ckpt_dir(out) not in checkpoint._ahead and n_done == plain[0]
    for x, y in zip(jax.tree.leaves(carry), jax.tree.leaves(plain[1]), strict=True):
        assert x.sharding == y.sharding
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_nothing_is_read_ahead_without_a_checkpoint_or_under_jax_distributed(whole, tmp_path,
                                                                            monkeypatch):
    """Under ``jax.distributed`` each process reads its own part at load, so none reads the
    whole carry ahead; a directory without a checkpoint has nothing to read."""
    cfg, out, _ = whole
    checkpoint.read_ahead(str(tmp_path))
    monkeypatch.setattr(jax.distributed, "is_initialized", lambda: True)
    checkpoint.read_ahead(out)
    roots = {checkpoint.ckpt_dir(str(tmp_path)), checkpoint.ckpt_dir(out)}
    assert not roots & set(checkpoint._ahead)


def test_loading_into_shapes_places_each_leaf_and_makes_the_empty_ones(tmp_path):
    """Shapes as the template: every leaf comes back shaped and placed as its shape says, the
    zero-size ones (never saved) made empty there."""
    import jax.numpy as jnp

    sharding = jax.sharding.SingleDeviceSharding(jax.devices()[0])
    carry = {"x": jnp.arange(6.0).reshape(2, 3), "n": jnp.array([1, 2]), "act": jnp.zeros((2, 0))}
    checkpoint.save(str(tmp_path), 1, carry)
    shapes = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding),
                          carry)
    n_done, loaded = checkpoint.load(str(tmp_path), shapes)
    assert n_done == 1
    for k, x in carry.items():
        assert loaded[k].shape == x.shape and loaded[k].dtype == x.dtype
        assert loaded[k].sharding == sharding
        np.testing.assert_array_equal(np.asarray(loaded[k]), np.asarray(x))


def test_a_saver_waits_for_each_write_before_the_next_and_keeps_the_last_two(tmp_path):
    """A save's files are written in the background: the next save waits for them before it
    removes all but the last two finished checkpoints, and leaving the block waits for the
    last one. A block that never saves writes nothing."""
    import jax.numpy as jnp

    root = checkpoint.ckpt_dir(str(tmp_path))
    with checkpoint.Saver(str(tmp_path)):
        pass
    assert not os.path.exists(root)
    carries = [{"x": jnp.full((2, 3), float(n))} for n in range(4)]
    with checkpoint.Saver(str(tmp_path)) as saver:
        for n in (1, 2, 3):
            saver.save(n, carries[n])
        # chunk 2 finished before chunk 3's save began; chunk 3 may still be writing
        assert checkpoint._checkpoints(root)[:2] == ["chunk_000001", "chunk_000002"]
    assert checkpoint._checkpoints(root) == ["chunk_000002", "chunk_000003"]
    n_done, loaded = checkpoint.load(str(tmp_path), carries[0])
    assert n_done == 3
    np.testing.assert_array_equal(np.asarray(loaded["x"]), np.asarray(carries[3]["x"]))


def test_no_readable_checkpoint_is_a_one_line_error(whole, tmp_path, capsys):
    cfg, _, _ = whole
    out = str(tmp_path / "cut")
    newest = _cut_after_three_chunks(cfg, out)
    _damage(newest, "random bytes")
    _damage(os.path.join(os.path.dirname(newest), "chunk_000002"), "emptied")
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        cli.main(["--resume", out, "--no-compile-cache"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "Traceback" not in err
    assert err.count("\n") == 1 and err.startswith(
        f"python -m flrjax.train: error: --resume: no checkpoint in "
        f"{checkpoint.ckpt_dir(out)} can be read (chunk_000003: "), err
    assert "; chunk_000002: " in err


def test_an_unreadable_resume_exits_in_one_line_while_programs_still_compile(whole, tmp_path,
                                                                             launch_env):
    """The CLI as a user runs it, on an empty compilation cache: the chunk still compiles in
    the background (:meth:`flrjax.launch_cache.Stored.prefetch`) when the restore fails. The
    process waits for it and exits with its one-line error and code 2 (a process that ends
    while XLA compiles in one of its threads aborts instead)."""
    import subprocess
    import sys

    cfg, _, _ = whole
    out = str(tmp_path / "cut")
    newest = _cut_after_three_chunks(cfg, out)
    _damage(newest, "emptied")
    _damage(os.path.join(os.path.dirname(newest), "chunk_000002"), "emptied")
    env = {**launch_env, "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "cache")}
    res = subprocess.run([sys.executable, "-m", "flrjax.train", "--resume", out], env=env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 2, res.stderr[-2000:]
    assert res.stderr.startswith("python -m flrjax.train: error: --resume: no checkpoint in ")
    assert res.stderr.count("\n") == 1, res.stderr[-2000:]


def test_a_checkpoint_padded_otherwise_restores_its_runs_and_pads_them_again(whole, capsys):
    """A run resumed over another number of devices pads its run axis otherwise: the saved
    runs come back first, and the padding runs are copies of the last one kept (more rows
    than saved), or the saved padding is left out (fewer). ``--resume`` takes ``--devices``
    (it places the runs, it does not change them), checked as a new run's, in one line."""

    cfg, out, _ = whole
    template = runner.init_carry(cfg, runner.build(cfg)[0], jax.random.PRNGKey(0))
    _, saved = checkpoint.load(out, template)
    for rows, ahead in ((cfg.runs + 2, False), (cfg.runs - 1, False), (cfg.runs + 2, True)):
        other = jax.tree.map(lambda x, n=rows: jax.numpy.concatenate(
            [x, jax.numpy.repeat(x[-1:], 2, 0)])[:n], template)
        if ahead:  # read on the host, then padded again there
            checkpoint.read_ahead(out)
        n_done, carry = checkpoint.load(out, other)
        assert n_done == 4 and jax.tree.structure(carry) == jax.tree.structure(template)
        for x, s, t in zip(jax.tree.leaves(carry), jax.tree.leaves(saved),
                           jax.tree.leaves(other), strict=True):
            assert x.shape == t.shape and x.dtype == t.dtype and x.sharding == t.sharding
            x, s = np.asarray(x), np.asarray(s)
            kept = min(rows, cfg.runs)
            np.testing.assert_array_equal(x[:kept], s[:kept])
            np.testing.assert_array_equal(x[kept:], np.repeat(s[kept - 1:kept], rows - kept, 0))
    assert cli.parse_cli(["--resume", out, "--devices", "1"]).cfg.devices == 1
    capsys.readouterr()
    with pytest.raises(SystemExit):
        cli.parse_cli(["--resume", out, "--devices", str(jax.device_count() + 1)])
    assert capsys.readouterr().err == (
        f"python -m flrjax.train: error: --resume: --devices must be in 1..{jax.device_count()}"
        f" (the visible devices), got {jax.device_count() + 1} (see --help)\n")
