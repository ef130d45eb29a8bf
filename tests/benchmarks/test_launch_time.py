"""launch_time: launches of a tiny run through the command line, each its own process."""

import json
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import launch_time  # noqa: E402

# four chunks of 400 steps on small networks: the launches need no learning
FLAGS = ("--env point3leg --algo flat --preset quick --hidden 16 --batch-size 32 "
         "--episodes-per-chunk 1 --initial-episodes 4 --eval-episodes 2 --steps 1600")


def test_warm_launches_new_other_values_and_resume_load_what_the_first_compiled(
        tmp_path, monkeypatch):
    """The first launch traces and compiles the trainer's programs (stored ones run as
    ``jit_call``); a new run, one with another learning rate and a resume load them: none
    compiles them again, and each writes its first row and the trainer's compile line."""
    monkeypatch.delenv("FLRJAX_PROGRAM_CACHE", raising=False)  # as a user launches it
    out = str(tmp_path / "launch.json")
    launch_time.main(["--flags", FLAGS, "--vary", "--lr-critic 5e-4", "--cache",
                      str(tmp_path / "cache"), "--runs", str(tmp_path / "runs"), "--out", out])
    with open(out) as f:
        result = json.load(f)
    first, *warm = result["launches"]
    assert [r["launch"] for r in result["launches"]] == [
        "first", "new_out", "other_values", "resume"]
    assert "jit_call" in {name for name, _ in first["compiled"]}
    for r in warm:
        assert "jit_call" not in {name for name, _ in r["compiled"]}, r["launch"]
        assert r["trace_s"] < first["trace_s"] and r["cache_hits"] > 0
    for r in result["launches"]:
        assert 0 < r["start_line_s"] < r["first_row_s"]
        assert r["first_chunk_s"] >= r["chunk_compile_s"] >= 0
        assert r["compiles"].startswith("compiles so far: tracing ")
    assert [r["compiles"].endswith("0 compiled") for r in result["launches"]] == [
        False, True, True, True]
    assert result["commit"] and "clean" in result
    assert warm[-1]["command"].startswith("python -m flrjax.train --resume ")


def test_a_failed_launch_says_why(tmp_path):
    with pytest.raises(SystemExit, match="(?s)launch first wrote no row.*unknown env 'nowhere'"):
        launch_time.main(["--flags", "--env nowhere --algo dhrl", "--cache",
                          str(tmp_path / "cache"), "--runs", str(tmp_path / "runs")])


def test_the_compile_log_splits_tracing_compiling_and_cache_loads():
    log = ["Finished tracing + transforming chunk for pjit in 2.5 sec",
           "Finished XLA compilation of jit(chunk) in 10.0 sec",
           "Persistent compilation cache hit for 'jit_init' with key 'k'",
           "Finished XLA compilation of jit(init) in 0.5 sec",
           "Finished tracing call for jit in 1.0 sec"]
    lines = [(float(i), line) for i, line in enumerate(log)]
    assert launch_time.compile_log(lines, until=3.5) == {
        "trace_s": 2.5, "compile_s": 10.0, "cache_load_s": 0.5, "cache_hits": 1,
        "compiled": [["jit_chunk", 10.0]], "loaded": [["jit_init", 0.5]]}
