"""One run over several processes through jax.distributed: two CPU processes of two devices
each train as one process of four devices, stop together and resume; the cluster detection
that turns it on by itself; its one-line errors."""

import csv
import os
import re
import socket
import subprocess
import sys

import pytest

from flrjax import distributed
from flrjax.metric_names import TIMES

# 5 seeds x 2 sweep points (10 runs, padded to 12 over 4 devices), two chunks of 400 steps
FLAGS = ["--env", "point3leg", "--algo", "flat", "--preset", "quick", "--seeds", "5",
         "--steps", "800", "--episodes-per-chunk", "1", "--initial-episodes", "4",
         "--eval-episodes", "2", "--hidden", "16", "--batch-size", "32",
         "--lr-critic", "1e-3,3e-4", "--no-compile-cache"]


def _env(devices: int) -> dict[str, str]:
    """The session's environment with ``devices`` CPU devices a process (its XLA flags kept)."""
    return {**os.environ, "XLA_FLAGS": os.environ.get("XLA_FLAGS", "")
            + f" --xla_force_host_platform_device_count={devices}"}


def _train(*args: str, devices: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "flrjax.train", *args], env=_env(devices),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _two_processes(flags: list[list[str]]) -> list[tuple[int, str, str]]:
    """(exit status, stdout, stderr) of processes 0 and 1, each with its ``flags`` and two
    devices, joined by a coordinator on a free localhost port."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    procs = [_train(*f, "--coordinator", f"localhost:{port}", "--num-processes", "2",
                    "--process-id", str(i), devices=2) for i, f in enumerate(flags)]
    outs = [p.communicate(timeout=600) for p in procs]
    return [(p.returncode, *o) for p, o in zip(procs, outs, strict=True)]


GLOO_WORDS = set(
    "[Gloo] Rank is connected to peer ranks. Expected number of connected peer ranks is :".split())


def _not_gloo(stdout: str) -> list[str]:
    """The words of ``stdout`` that are not gloo's "[Gloo] Rank 3 is connected to 3 peer
    ranks..." lines: gloo's threads write the pieces of those lines unsynchronised, so two of
    them can interleave into lines such as a bare "3"; its words and numbers are left out."""
    words = re.findall(r"\[Gloo\]|[^\s\d\[]+|\d+|\S", stdout)
    return [w for w in words if w not in GLOO_WORDS and not w.isdigit()]


def _metrics(out: str) -> list[dict]:
    with open(os.path.join(out, "metrics.csv")) as f:
        return [{k: v for k, v in r.items() if k not in TIMES}
                for r in csv.DictReader(f)]


def test_two_processes_train_as_one_of_four_devices_stop_together_and_resume(tmp_path):
    """Two processes of two CPU devices, the run axis over all four, against one process of
    four devices: process 1 alone has a time limit, so both stop after the first chunk
    (agreed, not left waiting in a collective), with one checkpoint written by both and the
    rows of that chunk written once, by process 0; resumed by both, the run's metrics.csv
    equals the one process's, bit for bit: each device trains the same 3 runs (10 padded to
    12) with the same program on the same inputs in both, and runs never exchange values,
    so nothing in the computation depends on which process holds a device."""
    one, cut = str(tmp_path / "one"), str(tmp_path / "cut")
    baseline = _train(*FLAGS, "--out", one, devices=4)
    first = _two_processes([[*FLAGS, "--out", cut], [*FLAGS, "--out", cut, "--time-limit",
                                                     "1e-9"]])
    assert baseline.wait(timeout=600) == 0, baseline.communicate()[1][-3000:]
    for rc, _, err in first:
        assert rc == 0, err[-3000:]
    assert os.listdir(os.path.join(cut, "checkpoints")) == ["chunk_000001"]
    assert len(_metrics(cut)) == 10
    assert "\ntime limit: stopped with a checkpoint (continue: " in first[0][1]
    # process 1 prints nothing (the lines of gloo, JAX's CPU collectives, are its own)
    assert _not_gloo(first[1][1]) == []
    resumed = _two_processes([["--resume", cut]] * 2)
    for rc, _, err in resumed:
        assert rc == 0, err[-3000:]
    assert _metrics(cut) == _metrics(one) and len(_metrics(one)) == 20
    assert os.path.exists(os.path.join(cut, "summary.json"))


SRUN = {"SLURM_JOB_ID": "7", "SLURM_STEP_NODELIST": "node[1-2]", "SLURM_PROCID": "0",
        "SLURM_LOCALID": "0"}


@pytest.mark.parametrize("env,processes", [
    ({}, 1),
    ({**SRUN, "SLURM_NTASKS": "4"}, 4),
    ({**SRUN, "SLURM_NTASKS": "1"}, 1),
    # a batch script or salloc shell (no step of srun): one process whatever the job's tasks
    ({"SLURM_JOB_ID": "7", "SLURM_NTASKS": "4", "SLURM_PROCID": "0"}, 1),
    ({"OMPI_MCA_orte_hnp_uri": "1.0;tcp://10.0.0.1:1234", "OMPI_COMM_WORLD_SIZE": "2"}, 2),
])
def test_several_processes_are_found_as_jax_finds_them(monkeypatch, env, processes):
    """:func:`distributed.launched_processes` reads what ``jax.distributed.initialize()``
    detects (srun's step, mpirun), and :func:`distributed.initialize` starts it by itself
    only where that is more than one process."""
    import jax

    for k in [k for k in os.environ if k.startswith(("SLURM_", "OMPI_"))]:
        monkeypatch.delenv(k)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    calls = []
    monkeypatch.setattr(jax.distributed, "is_initialized", lambda: False)
    monkeypatch.setattr(jax.distributed, "initialize", lambda *a: calls.append(a))
    assert distributed.launched_processes() == processes
    assert distributed.initialize(False) == (processes > 1)
    assert calls == ([(None, None, None)] if processes > 1 else [])


def test_distributed_without_its_coordinator_is_a_one_line_error(tmp_path):
    """Outside a cluster's launcher ``--num-processes`` needs ``--coordinator`` and
    ``--process-id``: one line saying so, before anything is written."""
    out = tmp_path / "run"
    proc = _train(*FLAGS, "--num-processes", "2", "--out", str(out), devices=1)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2 and "Traceback" not in err
    assert err.splitlines()[-1] == (
        "python -m flrjax.train: error: --distributed: coordinator_address should be defined. "
        "(outside SLURM's srun and Open MPI's mpirun give --coordinator, --num-processes and "
        "--process-id) (see --help)")
    assert not out.exists()


@pytest.mark.parametrize("argv,may", [
    (["--env", "ant3leg", "--seeds", "5"], False),
    (["--devices", "2", "--resume", "runs/x"], False),
    (["--distributed"], True),
    (["--dist"], True),  # argparse's abbreviation
    (["--d"], True),  # --devices or --distributed: argparse refuses it, no backend meanwhile
    (["--coordinator=host:1234"], True),
    (["--num-p", "2"], True),
    (["--process-id", "0"], True),
])
def test_a_backend_starts_early_only_where_jax_distributed_cannot_follow(monkeypatch, argv,
                                                                         may):
    """``python -m flrjax.train`` starts JAX's backend in a thread while it imports, but never
    where ``jax.distributed`` may start (it must come first): its flags or their abbreviations,
    a cluster launcher's processes; nor for ``--help``. The flags are the command line's."""
    from flrjax import cli

    for k in [k for k in os.environ if k.startswith(("SLURM_", "OMPI_"))]:
        monkeypatch.delenv(k)
    assert distributed.may_start(argv) == may
    thread = distributed.start_backend(argv)
    assert (thread is None) == may
    if thread is not None:
        thread.join(timeout=60)
        assert not thread.is_alive()
    assert distributed.start_backend([*argv, "--help"]) is None
    for k, v in {**SRUN, "SLURM_NTASKS": "2"}.items():
        monkeypatch.setenv(k, v)
    assert distributed.may_start(argv) and distributed.start_backend(argv) is None
    hosts = {s for a in cli._parser()._actions for s in a.option_strings
             if a.dest in ("distributed", "coordinator", "num_processes", "process_id")}
    assert hosts == set(distributed.FLAGS)
