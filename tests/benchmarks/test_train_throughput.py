"""train_throughput: job parsing, the breakdown arithmetic, and a tiny grid on the point mass
(timed on the CPU, resumed from its own output)."""

import argparse
import json
import os
import subprocess
import sys

import pytest

from flrjax.algos import flr

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import train_throughput as tt  # noqa: E402


def _args(**kw) -> argparse.Namespace:
    base = dict(env="point4leg", configs="1x1", protocols="paper,fast", measures="flat",
                episode_length=40, repeats=2, value_chunk=None)
    return argparse.Namespace(**{**base, **kw})


def test_jobs_per_config_protocol_and_measure():
    jobs = tt.parse_jobs(_args(configs="1x1,5x16:fast:flat+flr_dhrl@2",
                               measures="physics,flat"))
    assert [tt.job_key(j) for j in jobs] == [
        "1x1:paper:physics", "1x1:paper:flat",  # fast at one env is the paper protocol
        "5x16:fast:flat", "5x16:fast:flr_dhrl@2"]
    assert jobs[-1]["devices"] == 2
    assert tt.updates_per_step("fast", 16) == 1 / 16 and tt.updates_per_step("paper", 16) == 1
    assert tt.updates_per_step("0.25", 16) == 0.25
    with pytest.raises(ValueError, match="unknown protocol"):
        tt.updates_per_step("slow", 16)
    with pytest.raises(SystemExit):
        tt.parse_jobs(_args(configs="2x2:fast:physics@2"))
    assert tt.job_config(jobs[1]).algo == "flat"
    assert tt.job_config({**jobs[1], "measure": "flat_noupd"}).algo == "flat"
    with pytest.raises(SystemExit, match="no updates-alone step"):  # only flat offers one
        tt.parse_jobs(_args(measures="dhrl_noupd"))
    with pytest.raises(SystemExit):  # the first call starts from an empty buffer: never timed
        tt.main(["--repeats", "0"])


def test_value_chunk_reaches_the_flr_jobs_only_when_given():
    plain = tt.parse_jobs(_args(measures="flat,flr_dhrl"))
    assert all("value_chunk" not in j for j in plain)  # earlier results' jobs stay the same
    assert tt.job_config(plain[1]).flr_value_chunk is None
    flat_job, flr_job = tt.parse_jobs(_args(measures="flat,flr_dhrl", value_chunk=0))[:2]
    assert "value_chunk" not in flat_job and flr_job["value_chunk"] == 0
    cfg = tt.job_config(flr_job)
    assert cfg.flr_value_chunk == 0 and flr.from_run(cfg).value_chunk is None
    assert flr.from_run(tt.job_config({**flr_job, "value_chunk": 256})).value_chunk == 256
    with pytest.raises(SystemExit):
        tt.main(["--value-chunk", "-1"])
    # a result timed with another chunk (or none) is not silently reused
    done = {tt.job_key(j): {"job": j} for j in plain}
    assert tt.other_value_chunk(plain, done) == []
    assert tt.other_value_chunk([flat_job, flr_job], done) == [tt.job_key(flr_job)]


def test_breakdown_fractions_and_scaling():
    job = dict(env="ant4leg", seeds=5, envs=16, protocol="fast", devices=1, episode_length=80)
    ms = dict(physics=4.0, flat_noupd=5.0, flat=6.0, dhrl=9.0, flr_dhrl=10.0)
    results = {m: {"job": {**job, "measure": m}, "ms_per_iter": v, "chunk_gib": 1.0}
               for m, v in ms.items()}
    results["flat_noupd"]["updates_alone_ms_per_iter"] = 1.5
    results["two"] = {"job": {**job, "measure": "flr_dhrl", "devices": 2}, "ms_per_iter": 5.0}
    (row,) = tt.summarise(results)
    b = row["flr_dhrl_breakdown"]
    assert b == pytest.approx({"physics": 0.4, "act_store": 0.1, "updates_her": 0.1,
                               "planning_high_level": 0.3, "flr": 0.1})
    assert row["flr_dhrl_fraction_of_raw_physics"] == pytest.approx(0.4)
    assert row["flat_over_physics_plus_updates"] == pytest.approx(6.0 / 5.5)
    assert row["flr_dhrl@2_speedup"] == pytest.approx(2.0)
    assert row["flr_dhrl_env_steps_per_s"] == pytest.approx(80 / 10.0 * 1e3)
    assert row["flr_dhrl_updates_per_s"] == pytest.approx(
        row["flr_dhrl_env_steps_per_s"] * row["updates_per_step"])
    assert "physics_updates_per_s" not in row


def test_point_mass_grid_times_then_skips_done_jobs(tmp_path):
    """In a subprocess: the run switches on JAX's persistent compilation cache, which must not
    leak into the other tests' process."""
    out = tmp_path / "tt.json"
    argv = [sys.executable, tt.__file__, "--env", "point4leg", "--configs",
            "1x2:fast:flat_noupd", "--episode-length", "40", "--repeats", "1", "--cache",
            str(tmp_path / "cache"), "--out", str(out)]
    first = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    assert "1x2:fast:flat_noupd:" in first.stdout
    (row,) = json.loads(out.read_text())["rows"]
    assert row["flat_noupd_ms_per_iter"] > 0 and row["updates_alone_ms_per_iter"] > 0
    assert row["flat_noupd_chunk_gib"] > 0 and row["updates_per_step"] == 0.5
    assert json.loads(out.read_text())["jobs"]["1x2:fast:flat_noupd"]["job"]["repeats"] == 1
    again = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "1x2:fast:flat" not in again.stdout  # no job ran again
    assert json.loads(out.read_text())["rows"] == [row]
