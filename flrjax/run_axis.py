"""The run axis: every run of a program (seeds x sweep points) side by side, padded to a
multiple of the devices and split over them, each device running its own runs.

The programs' inputs and outputs are split along the run axis (:func:`shard_seeds`) and XLA
partitions the vmapped programs along it. Runs never interact, so each device trains
``padded_runs / devices`` runs with no communication but one: the ant's physics solver is a
while loop that, vmapped, runs until every run's solver converged, so its condition is
all-reduced across the devices each iteration (tests/test_runner.py checks the compiled
chunk). Not a ``shard_map`` over the whole program (each device a one-device program): XLA's
GPU compiler crashes on it for the ant (docs/benchmarks.md); only the fused Pallas kernel,
which XLA cannot partition, is a ``shard_map`` (:func:`vmap_runs`). The padding runs train
with the last run's values and their own keys, and no output shows them (:func:`real_runs`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import distributed
from flrjax.algos.common import num_devices, padded_runs
from flrjax.config import TrainConfig, sweep_points


def shard_seeds(cfg: TrainConfig) -> jax.sharding.NamedSharding:
    """Sharding of arrays with a leading run axis (:func:`padded_runs` long) over
    :func:`num_devices` devices.

    Under ``jax.distributed``, ``jax.devices()`` lists every process's devices.
    """
    mesh = jax.sharding.Mesh(np.array(jax.devices()[:num_devices(cfg)]), ("seeds",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("seeds"))


def vmap_runs(cfg: TrainConfig, fn):
    """``fn`` vmapped over the run axis. Split over devices, the vmap names the mesh's axis
    and traces under its abstract mesh, so that a ``shard_map`` inside ``fn`` (the fused
    kernel's, :func:`fused_value._per_device`) runs each device's own runs."""
    if num_devices(cfg) == 1:
        return jax.vmap(fn)
    mesh = shard_seeds(cfg).mesh.abstract_mesh
    runs = jax.vmap(fn, spmd_axis_name="seeds")

    def split(*args):
        with jax.sharding.use_abstract_mesh(mesh):
            return runs(*args)

    return split


def pad_runs(cfg: TrainConfig, tree):
    """``tree``'s leaves ``[runs, ...]`` (host arrays) with the padding runs' rows appended,
    copies of the last run's: ``[padded_runs, ...]``, so that each padding run trains with
    valid values (a sweep point's)."""
    extra = padded_runs(cfg) - cfg.runs
    return jax.tree.map(lambda x: np.concatenate([x, np.repeat(x[-1:], extra, 0)]), tree)


def real_runs(cfg: TrainConfig, tree):
    """``tree``'s leaves ``[padded_runs, ...]`` whole on the host (:func:`distributed.gather`),
    the padding runs dropped."""
    return jax.tree.map(lambda x: x[:cfg.runs], distributed.gather(tree))


#: Folded into a run's key for the padding runs' keys, apart from every real run's.
PADDING_KEY = 0x7ADD


def run_keys(cfg: TrainConfig, key: jax.Array) -> jax.Array:
    """One key per run ``[padded_runs, 2]``: ``key`` split over the seeds, the same for every
    sweep point, so that seed ``s`` of each point meets the same randomness as in a plain run;
    then the padding runs' own keys (:func:`padded_runs`), from ``key`` folded with
    :data:`PADDING_KEY`, which leave the real runs' keys as without padding."""
    keys = jnp.tile(jax.random.split(key, cfg.seeds), (len(sweep_points(cfg)), 1))
    extra = padded_runs(cfg) - cfg.runs
    if not extra:
        return keys
    return jnp.concatenate([keys, jax.random.split(jax.random.fold_in(key, PADDING_KEY),
                                                   extra)])
