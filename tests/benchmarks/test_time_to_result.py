"""time_to_result: DHRL and FLR+DHRL in one program until FLR+DHRL's success reaches the
threshold, resumable across calls, at a tiny size on the point mass. Each call in its own
process, as a user runs it: the benchmark loads the programs it compiled ahead from the
compilation cache, which stays out of the test session. The tests share one such cache (the
same programs each time) and the traced programs stored beside it: only the first call traces
and compiles cold."""

import json
import os
import subprocess
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import time_to_result as ttr  # noqa: E402

# three chunks of 400 env steps: 4 envs, one 100-step episode each
FLAGS = ("--env point3leg --seeds 2 --preset quick --steps 1200 --episodes-per-chunk 1 "
         "--num-envs 4 --hidden 16 --batch-size 32 --buffer-episodes 40 --initial-episodes 4")


@pytest.fixture(scope="module")
def cache(tmp_path_factory, launch_env):
    """(the calls' compilation cache, their environment: traced programs kept too)"""
    return str(tmp_path_factory.mktemp("ttr-cache") / "jax"), launch_env


def _run(tmp_path, cache, *argv, flags=FLAGS, devices=1):
    cache, env = cache
    if devices > 1:  # that many CPU devices in the call's process
        env = {**env, "XLA_FLAGS": env.get("XLA_FLAGS", "")
               + f" --xla_force_host_platform_device_count={devices}"}
    subprocess.run([sys.executable, ttr.__file__, "--out", str(tmp_path / "out"), "--flags",
                    flags, "--cache", cache, *argv], check=True, capture_output=True,
                   timeout=600, env=env)
    with open(tmp_path / "out" / f"{ttr.device_slug('cpu', 'cpu', devices)}.json") as f:
        return json.load(f)


def test_device_names():
    assert ttr.device_slug("NVIDIA H100 80GB HBM3", "gpu") == "h100"
    assert ttr.device_slug("NVIDIA H200", "gpu") == "h200"
    assert ttr.device_slug("cpu", "cpu") == "cpu"
    assert ttr.device_slug("NVIDIA H200", "gpu", 2) == "h200x2"  # not the file of one H200
    assert ttr.device_slug("cpu", "cpu", 4) == "cpux4"


def test_stops_at_the_threshold_and_writes_the_result(tmp_path, cache):
    r = _run(tmp_path, cache, "--threshold", "0")  # reached at the first evaluation
    assert r["seconds_to_threshold"]["flr_dhrl"] == r["curve"][0]["seconds"] > r["compile_s"] > 0
    assert r["env_steps_to_threshold"] == {"dhrl": 400, "flr_dhrl": 400}
    assert len(r["curve"]) == 1 and r["finished"] and r["devices"] == 1
    for key in ("device", "command", "threshold", "compile_s", "seconds_to_threshold",
                "env_steps_to_threshold", "curve"):
        assert key in r
    assert set(r["curve"][0]) == {"seconds", "env_steps", "chunk_s", "eval_s", "dhrl", "flr_dhrl"}
    assert r["curve"][0]["chunk_s"] > 0 and r["curve"][0]["eval_s"] > 0
    assert os.path.getsize(tmp_path / "out" / "cpu.png") > 0


def test_past_threshold_trains_on_to_the_last_step(tmp_path, cache):
    r = _run(tmp_path, cache, "--threshold", "0", "--past-threshold")
    assert [c["env_steps"] for c in r["curve"]] == [400, 800, 1200] and r["finished"]
    assert r["env_steps_to_threshold"] == {"dhrl": 400, "flr_dhrl": 400}


def test_a_split_run_adds_up_its_calls(tmp_path, cache):
    first = _run(tmp_path, cache, "--threshold", "2", "--time-limit", "0.001")  # one chunk
    assert not first["finished"] and [r["env_steps"] for r in first["curve"]] == [400]
    second = _run(tmp_path, cache, "--threshold", "2")  # never reached: runs to --steps
    assert second["finished"] and second["seconds_to_threshold"]["flr_dhrl"] is None
    assert [r["env_steps"] for r in second["curve"]] == [400, 800, 1200]
    assert second["curve"][0] == first["curve"][0]
    assert len(second["calls"]) == 2
    assert second["calls"][1]["start_s"] == first["calls"][0]["end_s"]
    assert second["curve"][1]["seconds"] > second["calls"][1]["start_s"]


def test_two_devices_measure_apart_from_one(tmp_path, cache):
    """An unfinished measurement on one device is not continued by the same command split over
    two: that one starts its own file and run."""
    one = _run(tmp_path, cache, "--threshold", "2", "--time-limit", "0.001")
    two = _run(tmp_path, cache, "--threshold", "0", flags=FLAGS + " --devices 2", devices=2)
    assert two["devices"] == 2 and len(two["calls"]) == 1 and two["run_dir"] != one["run_dir"]
    assert [r["env_steps"] for r in two["curve"]] == [400] and two["finished"]
    with open(tmp_path / "out" / "cpu.json") as f:
        assert json.load(f) == one
