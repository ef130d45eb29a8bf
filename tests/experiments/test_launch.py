"""A grid's programs placed on a host's GPUs (a fake GPU list: trivial child commands see
their CUDA_VISIBLE_DEVICES), through submitit's local executor, and SLURM's job parameters."""

import argparse
import os
import re
import signal
import stat
import sys
import threading
import time

import pytest

# imported as the tests are collected, not first within a test: importing submitit configures
# logging (logging.config.dictConfig), which closes the handlers there are, among them absl's,
# whose stream inside a test would be a capture of pytest's that later tests still use
import submitit  # noqa: F401

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import launch  # noqa: E402

#: A program: writes the GPUs it sees and how many programs run with it (each holds a marker
#: file in ``running/`` for ``hold`` seconds; the two of ``pair`` wait for each other, up to
#: 20 s, as jobs start at uneven speeds) to ``seen/<name>``; ``fail`` ends it with an error on
#: stderr.
CHILD = """
import os, sys, time
root, name, hold, fail, pair, left = sys.argv[1:]
marker = os.path.join(root, "running", name)
open(marker, "w").close()
running = lambda: len(os.listdir(os.path.join(root, "running")))
start = time.time()
while name in pair.split(",") and running() < 2 and time.time() < start + 20:
    time.sleep(0.01)
together = running()
time.sleep(float(hold))
with open(os.path.join(root, "seen", name), "w") as f:
    f.write(f"{os.environ.get('CUDA_VISIBLE_DEVICES')!r} {together} {left}")
os.remove(marker)
print(f"{name}: done")
if fail == "1":
    sys.exit(f"{name}: broken on purpose")
"""


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    p.add_argument("--time-limit", type=float, default=None)
    launch.add_arguments(p)
    return p.parse_args(argv)


def _command(root, hold=0.3, fail=(), pair=""):
    for d in ("running", "seen"):
        os.makedirs(os.path.join(root, d), exist_ok=True)
    return lambda name, left: [sys.executable, "-c", CHILD, str(root), name, str(hold),
                               "1" if name in fail else "0", pair, repr(left)]


def _seen(root) -> dict[str, tuple[str, int, str]]:
    out = {}
    for name in os.listdir(os.path.join(root, "seen")):
        gpus, together, left = open(os.path.join(root, "seen", name)).read().split(" ")
        out[name] = (eval(gpus), int(together), left)
    return out


def test_visible_gpus_from_the_flag_cuda_visible_devices_or_nvidia_smi(tmp_path, monkeypatch):
    assert launch.visible_gpus("2,3") == ["2", "3"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0, 1,-1,2")  # CUDA stops at an invalid id
    assert launch.visible_gpus() == ["0", "1"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "")
    assert launch.visible_gpus() == []
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    smi = tmp_path / "nvidia-smi"
    smi.write_text("#!/bin/sh\necho 'GPU 0: NVIDIA H100 (UUID: GPU-a)'\n"
                   "echo '  MIG 1g.10gb Device 0: (UUID: MIG-b)'\n"
                   "echo 'GPU 1: NVIDIA H100 (UUID: GPU-c)'\n")
    smi.chmod(smi.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", str(tmp_path))
    assert launch.visible_gpus() == ["0", "1"]
    smi.unlink()
    assert launch.visible_gpus() == []  # no nvidia-smi: no GPU


def test_slots_group_gpus_per_program_and_leave_one_gpu_to_this_process(monkeypatch):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1,2,3,4")
    assert launch.slots(_args()) == ["0", "1", "2", "3", "4"]
    assert launch.slots(_args("--gpus-per-program", "2")) == ["0,1", "2,3"]
    assert launch.slots(_args("--gpus-per-program", "5")) is None  # one program: in process
    assert launch.slots(_args("--gpus", "3")) == ["3"]  # named: placed there
    with pytest.raises(SystemExit, match="--gpus-per-program 6 of 5 GPUs"):
        launch.slots(_args("--gpus-per-program", "6"))
    with pytest.raises(SystemExit, match="names no GPU"):
        launch.slots(_args("--gpus", "-1"))
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "")
    assert launch.slots(_args()) is None  # no GPU: one after the other in this process
    assert launch.slots(_args("--submitit", "local")) == [None]  # ... or one job at a time


def test_jax_starts_without_preallocating_and_the_programs_get_the_environment_back(
        monkeypatch):
    """JAX starts in the placing process with preallocation off (its first arrays would take
    most of the first GPU's memory), and the environment the programs inherit is as before."""
    seen = []
    monkeypatch.setattr(launch.jax, "devices", lambda: seen.append(
        os.environ.get(launch.PREALLOCATE)))
    monkeypatch.delenv(launch.PREALLOCATE, raising=False)
    launch.start_jax_without_preallocating()
    assert seen == ["false"] and launch.PREALLOCATE not in os.environ
    monkeypatch.setenv(launch.PREALLOCATE, "true")
    launch.start_jax_without_preallocating()
    assert seen == ["false", "false"] and os.environ[launch.PREALLOCATE] == "true"


@pytest.mark.parametrize("placement", [(), ("--submitit", "local")], ids=["process", "submitit"])
def test_programs_run_one_per_gpu_and_a_failure_leaves_the_others(tmp_path, capsys, placement):
    """Four programs on two (fake) GPUs: each sees one GPU, never more than two run at once,
    and the one that fails is reported in one line while the others run."""
    names = ["a", "b", "bad", "c"]
    with pytest.raises(launch.Failed, match="1 of 4 programs failed: bad"):
        launch.run(names, _command(tmp_path, fail={"bad"}, pair="a,b"),
                   _args("--gpus", "0,1", *placement), str(tmp_path / "runs"), deadline=None,
                   time_limit=None)
    seen = _seen(tmp_path)
    assert sorted(seen) == names
    assert {gpus for gpus, _, _ in seen.values()} == {"0", "1"}
    assert max(n for _, n, _ in seen.values()) == 2
    out, err = capsys.readouterr()
    assert not any(ln.startswith("bad (") for ln in out.splitlines())
    line = next(ln for ln in err.splitlines() if ln.startswith("bad ("))
    assert "failed" in line and line.split("; log ")[0].endswith("bad: broken on purpose")
    log = line.split("; log ")[1]
    assert "bad: broken on purpose" in open(log).read()  # its own log
    for name in ("a", "c"):
        assert f"{name} (" in out and f"): {name}: done" in out
    if not placement:
        assert sorted(os.listdir(tmp_path / "runs" / "logs")) == [f"{n}.log" for n in names]


def test_no_program_starts_after_the_deadline_and_each_gets_the_time_left(tmp_path, capsys):
    launch.run(["a", "b"], _command(tmp_path, hold=0.0), _args("--gpus", "0"),
               str(tmp_path), deadline=time.perf_counter() + 60, time_limit=60)
    assert all(0 < float(left) <= 60 for _, _, left in _seen(tmp_path).values())
    launch.run(["c"], _command(tmp_path), _args("--gpus", "0"), str(tmp_path),
               deadline=time.perf_counter(), time_limit=60)
    assert "time limit: c not started" in capsys.readouterr().out
    assert "c" not in _seen(tmp_path)


def test_a_signal_starts_no_more_programs_and_lets_the_running_one_end(tmp_path, capsys):
    """SIGTERM to this process alone: the running program (which a scheduler or Ctrl-C would
    signal itself) ends; the next ones are not started; exit status 128 + SIGTERM."""
    handler = signal.getsignal(signal.SIGTERM)
    threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGTERM)).start()
    with pytest.raises(SystemExit) as stop:
        launch.run(["a", "b", "c"], _command(tmp_path, hold=0.6), _args("--gpus", "0"),
                   str(tmp_path), deadline=None, time_limit=None)
    assert stop.value.code == 128 + signal.SIGTERM
    assert list(_seen(tmp_path)) == ["a"]
    assert "run the same command again" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is handler  # restored


#: A SLURM cluster of one host for the tests: ``sbatch`` runs (a copy of) the job script in the
#: background with the variables SLURM gives a job's task, ``srun`` runs its command into
#: ``--output``, ``sacct`` knows no job (submitit then waits for the job's result file). Unlike
#: SLURM's, these jobs start at once: the script runs from its copy, which submitit cannot move
#: away, and srun makes the output's folder, which submitit may not have made yet.
FAKE_SLURM = {
    "sbatch": """#!/bin/bash
script="$(dirname "$1")/../sbatch_$$.sh"
cp "$1" "$script"
(export SLURM_JOB_ID=$$ SLURM_NTASKS=1 SLURM_JOB_NUM_NODES=1 SLURM_NODEID=0 SLURM_PROCID=0 \\
    SLURM_LOCALID=0 SLURM_JOB_NODELIST=localhost; bash "$script") >/dev/null 2>&1 &
echo "Submitted batch job $$"
""",
    "srun": """#!/bin/bash
while [[ $1 == --* ]]; do
    if [[ $1 == --output ]]; then out=${2//%j/$SLURM_JOB_ID}; shift; fi
    shift
done
mkdir -p "$(dirname "${out//%t/0}")"
exec "$@" >> "${out//%t/0}" 2>&1
""",
    "sacct": "#!/bin/bash\necho 'JobID|State|NodeList'\n",
}


def test_slurm_jobs_run_with_the_partition_gpus_time_and_extra_sbatch_options(tmp_path,
                                                                            monkeypatch):
    """Through a pretended SLURM cluster (:data:`FAKE_SLURM`): every program is a job at once,
    each job's sbatch script asks for the partition, the GPUs, the time limit and a margin,
    and the extra options; a failed job is reported and the others run."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, script in FAKE_SLURM.items():
        (bin_dir / name).write_text(script)
        (bin_dir / name).chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:{os.environ['PATH']}")
    monkeypatch.setattr(launch, "SLURM_POLL_S", launch.POLL_S)
    args = _args("--submitit", "slurm", "--slurm-partition", "gpu", "--gpus-per-program", "2",
                 "--slurm-param", "account=proj", "--slurm-param", "cpus-per-task=8")
    with pytest.raises(launch.Failed, match="1 of 3 programs failed: bad"):
        launch.run(["a", "b", "bad"], _command(tmp_path, fail={"bad"}, pair="a,b"), args,
                   str(tmp_path / "fig2"), deadline=None, time_limit=3600)
    seen = _seen(tmp_path)
    assert sorted(seen) == ["a", "b", "bad"] and seen["a"][1] >= 2  # side by side (3: bad too)
    assert {left for _, _, left in seen.values()} == {"3600"}  # each job its whole limit
    scripts = sorted((tmp_path / "fig2").glob("sbatch_*.sh"))
    assert len(scripts) == 3
    for script in scripts:
        text = script.read_text()
        for line in ("--partition=gpu", "--gpus-per-node=2", "--account=proj",
                     "--cpus-per-task=8", "--nodes=1", "--ntasks-per-node=1",
                     f"--time={60 + launch.SLURM_MARGIN_S // 60}"):
            assert f"#SBATCH {line}\n" in text
    assert sorted(re.search("--job-name=(.*)", s.read_text())[1] for s in scripts) == [
        "fig2.a", "fig2.b", "fig2.bad"]


def test_bad_placement_flags_are_one_line_errors(tmp_path, monkeypatch, capsys):
    def run(*argv, time_limit=None):
        launch.run(["a"], _command(tmp_path), _args(*argv), str(tmp_path), None, time_limit)

    with pytest.raises(SystemExit, match="needs --time-limit SECONDS"):
        run("--submitit", "slurm")
    with pytest.raises(SystemExit, match=r'--submitit slurm: Could not detect "srun"'):
        run("--submitit", "slurm", time_limit=60)  # no SLURM here
    with pytest.raises(SystemExit, match="--slurm-param takes KEY=VALUE"):
        run("--submitit", "slurm", "--slurm-param", "account", time_limit=60)
    with pytest.raises(SystemExit, match="takes GPU indices, not GPU-a"):
        run("--submitit", "local", "--gpus", "GPU-a")
    with pytest.raises(SystemExit, match=r"--gpus-per-program 0"):
        run("--gpus-per-program", "0")
    monkeypatch.setitem(sys.modules, "submitit", None)  # not installed
    with pytest.raises(SystemExit, match=r"needs submitit: pip install 'flrjax\[cluster\]'"):
        run("--submitit", "local")
    with pytest.raises(SystemExit) as usage:
        _args("--submitit", "lsf")
    assert usage.value.code == 2
    assert "invalid choice: 'lsf'" in capsys.readouterr().err
    assert not _seen(tmp_path)  # nothing ran
