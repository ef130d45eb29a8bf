"""One run over several processes (hosts) through ``jax.distributed``, JAX's own runtime.

Every process runs the same program on the same inputs; ``jax.devices()`` then lists every
process's devices and the run axis is split over all of them (:func:`flrjax.run_axis.shard_seeds`).
Metrics are gathered to every process (:func:`gather`), process 0 alone writes the run's files
(:func:`is_main`), checkpoints are written and read by all through orbax, and decisions to
stop are agreed (:func:`agree`) so that no process waits in a collective for another
that stopped. The run directory must be on a file system every process sees.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence

import jax
import numpy as np

from flrjax.options import ConfigError

#: The command line's flags that start ``jax.distributed`` (:func:`initialize`).
FLAGS = ("--distributed", "--coordinator", "--num-processes", "--process-id")


def launched_processes() -> int:
    """How many processes the launcher of this one started, as ``jax.distributed``'s cluster
    detection reads it (``jax._src.clusters``): SLURM's ``srun`` (its variables
    ``SLURM_JOB_ID``, ``SLURM_STEP_NODELIST``, ``SLURM_NTASKS``, ``SLURM_PROCID``,
    ``SLURM_LOCALID``), Open MPI's ``mpirun`` (``OMPI_MCA_orte_hnp_uri``,
    ``OMPI_COMM_WORLD_SIZE``); 1 elsewhere. A batch script or an allocation's shell that
    starts one process without ``srun`` lacks the step's variables: 1."""
    env = os.environ
    slurm = ("SLURM_JOB_ID", "SLURM_STEP_NODELIST", "SLURM_NTASKS", "SLURM_PROCID",
             "SLURM_LOCALID")
    try:
        if all(k in env for k in slurm):
            return int(env["SLURM_NTASKS"])
        if "OMPI_MCA_orte_hnp_uri" in env:
            return int(env.get("OMPI_COMM_WORLD_SIZE", "1"))
    except ValueError:
        return 1
    return 1


def initialize(distributed: bool, coordinator: str | None = None,
               num_processes: int | None = None, process_id: int | None = None) -> bool:
    """Start ``jax.distributed`` before anything touches JAX's backend: when asked
    (``distributed``, or any of the other arguments given), or when a cluster's launcher
    started several processes (:func:`launched_processes`; a single process is left alone).
    The arguments it is not given it detects (SLURM, Open MPI; the coordinator also from
    ``$JAX_COORDINATOR_ADDRESS``). Returns whether it started; a failure is a
    :class:`ConfigError` naming what to give."""
    asked = distributed or any(x is not None for x in (coordinator, num_processes, process_id))
    if not (asked or launched_processes() > 1) or jax.distributed.is_initialized():
        return False
    try:
        jax.distributed.initialize(coordinator, num_processes, process_id)
    except (ValueError, RuntimeError, TypeError) as e:
        msg = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ConfigError(f"--distributed: {msg} (outside SLURM's srun and Open MPI's mpirun "
                          "give --coordinator, --num-processes and --process-id)") from None
    return True


def may_start(argv: Sequence[str]) -> bool:
    """Whether the command line ``argv`` may start ``jax.distributed``: one of :data:`FLAGS`
    given, or a prefix of one (argparse takes abbreviations), or a cluster launcher started
    several processes (:func:`launched_processes`)."""
    names = [a.split("=", 1)[0] for a in argv if a.startswith("--") and len(a) > 2]
    return launched_processes() > 1 or any(f.startswith(n) for n in names for f in FLAGS)


def start_backend(argv: Sequence[str]) -> threading.Thread | None:
    """Start JAX's backend in a background thread with a first tiny program, so that the
    device's start (on a GPU its context and the compiler's first use: seconds) overlaps the
    trainer's imports and checks instead of following them; None where ``argv`` asks for
    ``--help`` or :func:`may_start` ``jax.distributed``, which must come before any backend.
    Not a daemon thread: a process that ends sooner waits for it."""
    if may_start(argv) or {"-h", "--help"} & set(argv):
        return None
    thread = threading.Thread(target=_first_program, name="flrjax-backend")
    thread.start()
    return thread


def _first_program() -> None:
    try:
        jax.jit(lambda x: x + 1)(np.zeros(1, np.float32)).block_until_ready()
    except Exception:  # noqa: BLE001 (the trainer meets the same failure and reports it)
        return


def is_main() -> bool:
    """Whether this process writes the run's files and messages (process 0)."""
    return jax.process_index() == 0


def gather(tree):
    """``tree``'s arrays (global ones split over every process's devices) whole on this
    process's host, as numpy arrays."""
    if jax.process_count() == 1:
        return jax.tree.map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)


def put(x, sharding: jax.sharding.Sharding) -> jax.Array:
    """``x`` (the same on every process) as a global array of ``sharding``, each process
    placing its own part."""
    if jax.process_count() == 1:
        return jax.device_put(x, sharding)
    host = np.asarray(x)
    return jax.make_array_from_callback(host.shape, sharding, lambda idx: host[idx])


def agree(*values: int) -> tuple[int, ...]:
    """Each of ``values`` (ints, or bools), its largest over the processes: every process gets
    the same answers, e.g. to stop after a chunk when a signal or a time limit reached one
    (a bool is true where it is true on any)."""
    if jax.process_count() == 1:
        return tuple(int(v) for v in values)
    from jax.experimental import multihost_utils

    every = multihost_utils.process_allgather(np.array(values, np.int64))
    return tuple(int(v) for v in np.asarray(every).reshape(-1, len(values)).max(0))


def barrier(name: str) -> None:
    """Wait here until every process arrives (a no-op in one process)."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)
