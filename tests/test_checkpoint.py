"""Checkpoints: a run stopped (killed, out of time, SIGKILLed) resumes to the metrics of an
uninterrupted one."""

import csv
import dataclasses
import os

import pytest

from flrjax import cli, runner
from tests.tiny import TINY


def test_killed_run_resumes_to_identical_metrics(tmp_path):
    cfg = dataclasses.replace(TINY, seeds=2, steps=4 * TINY.steps_per_chunk)
    whole = runner.train(dataclasses.replace(cfg, out=str(tmp_path / "whole")), progress=False)
    out = str(tmp_path / "cut")
    runner.train(dataclasses.replace(cfg, out=out), progress=False, max_chunks=2)
    # a row written after the last checkpoint (as if killed between the two) is dropped
    with open(os.path.join(out, "metrics.csv"), "a") as f:
        f.write(",".join(["999"] * len(runner.metric_fields(cfg))) + "\n")
    resumed_cfg, resume = cli.parse_cli(["--resume", out])[:2]
    assert resume and resumed_cfg == dataclasses.replace(cfg, out=out)
    rows = runner.train(resumed_cfg, progress=False, resume=True)
    # the restored carry has the fresh one's types: one compiled chunk for all three runs
    _, chunk, evaluate = runner.build(cfg)
    assert chunk._cache_size() == 1 and evaluate._cache_size() == 1
    drop = ("wall_time", "env_steps_per_s")
    assert [{k: v for k, v in r.items() if k not in drop} for r in rows] == \
        [{k: v for k, v in r.items() if k not in drop} for r in whole]
    with open(os.path.join(out, "metrics.csv")) as f:
        assert len(list(csv.DictReader(f))) == len(whole)
    assert sorted(os.listdir(os.path.join(out, "checkpoints"))) == ["chunk_000003",
                                                                   "chunk_000004"]
    with pytest.raises(SystemExit):
        cli.parse_cli(["--resume", out, "--seeds", "3"])


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
