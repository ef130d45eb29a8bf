"""launch_time: a cold and a warm launch of a tiny run, each in its own process."""

import json
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import launch_time  # noqa: E402


def test_the_second_launch_loads_what_the_first_compiled(tmp_path):
    out = str(tmp_path / "launch.json")
    launch_time.main(["--flags", "--env point3leg --algo dhrl --preset quick --hidden 16 "
                      "--batch-size 32", "--cache", str(tmp_path / "cache"), "--out", out])
    with open(out) as f:
        cold, warm = json.load(f)["launches"]
    assert warm["build_compile_s"] < cold["build_compile_s"]
    for launch in (cold, warm):
        assert set(launch["program_s"]) == {"init", "chunk", "evaluate"}
        assert launch["import_s"] < launch["first_chunk_s"] < launch["total_s"]
    assert os.listdir(tmp_path / "cache")  # the cache was written


def test_a_failed_launch_says_why(tmp_path):
    with pytest.raises(SystemExit, match="(?s)launch 1 failed.*unknown env 'nowhere'"):
        launch_time.main(["--flags", "--env nowhere --algo dhrl", "--cache",
                          str(tmp_path / "cache")])
