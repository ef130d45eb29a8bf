"""A run's checkpoints: the whole carry (orbax) with a checksum of its bytes in
``OUT/checkpoints``, the last two kept, and the restore that continues a run as if
uninterrupted, from the newest checkpoint that reads back whole.

The carry is stored as the programs hold it, its run axis padded to a multiple of the devices
(:func:`flrjax.algos.common.padded_runs`). A run resumed over another number of devices, and
so another padding, restores the real runs and pads them again (:func:`_repad`)."""

from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import functools
import logging
import os
import re
import shutil
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from flrjax import distributed, launch_cache
from flrjax.config import ConfigError, TrainConfig, sweep_points

#: The key under which a checkpoint holds the checksum of its leaves (:func:`_checksum`).
CHECKSUM = "checksum"

#: Per checkpoints directory, the newest checkpoint's path and its read in flight
#: (:func:`read_ahead`), until :func:`load` takes it.
_ahead: dict[str, tuple[str, concurrent.futures.Future]] = {}


def ckpt_dir(out: str) -> str:
    return os.path.abspath(os.path.join(out, "checkpoints"))


def _checkpoints(root: str) -> list[str]:
    """The finished checkpoints in ``root``, oldest first. A write that was killed leaves an
    orbax temporary directory (``chunk_000003.orbax-checkpoint-tmp-...``): not one of them."""
    if not os.path.isdir(root):
        return []
    return sorted(d for d in os.listdir(root) if re.fullmatch(r"chunk_\d{6}", d))


def has_checkpoint(out: str) -> bool:
    """Whether the run directory ``out`` holds a finished checkpoint to ``--resume`` from."""
    return bool(_checkpoints(ckpt_dir(out)))


def _nonempty_leaves(carry) -> dict:
    """The carry's leaves by index, without the zero-size ones (orbax refuses them; MJX's
    ``Data`` has some, e.g. ``act`` of a model without actuator state). Restoring takes those
    from the template, where they are just as empty."""
    return {str(i): x for i, x in enumerate(jax.tree.leaves(carry)) if x.size}


class Saver:
    """A run's checkpoints, written while it trains on: :meth:`save` returns once the carry is
    copied off the devices (orbax's blocking phase) and the files are written in the
    background during the next chunk. A save waits for the previous one's files, then keeps
    the last two finished checkpoints; leaving the ``with`` block waits for the last. Orbax
    writes to a temporary directory and renames it when done, so a process killed mid-write
    leaves the previous checkpoint whole. Under ``jax.distributed`` every process saves its
    own part of the arrays and process 0 removes the old checkpoints."""

    def __init__(self, out: str):
        self.root = ckpt_dir(out)
        self._ckptr = None  # orbax's, made at the first save: a run may never save

    def __enter__(self) -> Saver:
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.wait()
        finally:
            if self._ckptr is not None:
                self._ckptr.close()

    def save(self, n_done: int, carry) -> None:
        """Checkpoint the carry after ``n_done`` chunks (replacing one of the same chunk: one
        that could not be read, trained again)."""
        import orbax.checkpoint as ocp

        self.wait()
        self._ckptr = self._ckptr or ocp.StandardCheckpointer()
        leaves = _nonempty_leaves(carry)
        self._ckptr.save(os.path.join(self.root, f"chunk_{n_done:06d}"),
                         {**leaves, CHECKSUM: _checksum(leaves)}, force=True)

    def wait(self) -> None:
        """Wait for the checkpoint being written, if any, then remove all but the last two."""
        if self._ckptr is None:
            return
        self._ckptr.wait_until_finished()
        if distributed.is_main():
            for old in _checkpoints(self.root)[:-2]:
                shutil.rmtree(os.path.join(self.root, old))


def save(out: str, n_done: int, carry) -> None:
    """Checkpoint the carry after ``n_done`` chunks and wait until it is written
    (:class:`Saver`, for one checkpoint)."""
    with Saver(out) as saver:
        saver.save(n_done, carry)


def load(out: str, template) -> tuple[int, object]:
    """(chunks done, carry) from the newest readable checkpoint in ``out``'s checkpoints, in
    ``template``'s structure, shapes, dtypes and shardings (arrays or ``ShapeDtypeStruct``s);
    reads nothing else. A checkpoint
    whose run axis (every leaf's first) is padded otherwise than ``template``'s is padded
    again (:func:`_repad`). A newer checkpoint that
    cannot be read (overwritten, truncated) is named in a one-line warning; none readable is
    a :class:`ConfigError`."""
    root = ckpt_dir(out)
    done = _checkpoints(root)
    if not done:
        raise ConfigError(f"--resume: no checkpoint in {root}")
    ahead_path, ahead = _ahead.pop(root, ("", None))
    want = _nonempty_leaves(template)
    keys, fold = _checksum_program(want)
    if isinstance(fold, launch_cache.Stored):  # loads while the checkpoint is read and placed
        fold.prefetch([want[k] for k in keys])
    leaves, treedef = jax.tree.flatten(template)
    unreadable: list[tuple[str, str]] = []  # (name, why)
    for name in reversed(done):
        path = os.path.join(root, name)
        try:
            saved = _read(path, want, ahead if path == ahead_path else None)
        except Exception as e:  # orbax and tensorstore raise many kinds on damaged files
            unreadable.append((name, _one_line(e)))
            continue
        for bad, why in unreadable:
            warnings.warn(f"--resume: checkpoint {os.path.join(root, bad)} cannot be read "
                          f"({why}); restoring the older {name}", CheckpointWarning,
                          stacklevel=2)
        carry = jax.tree.unflatten(treedef, [saved[str(i)] if str(i) in saved else _empty(x)
                                             for i, x in enumerate(leaves)])
        return int(name.split("_")[1]), carry
    raise ConfigError(f"--resume: no checkpoint in {root} can be read "
                      f"({'; '.join(f'{bad}: {why}' for bad, why in unreadable)})")


def _empty(x) -> jax.Array:
    """A zero-size leaf (none is saved) shaped and placed as ``x`` (put, not computed: no
    program to compile for it)."""
    return x if isinstance(x, jax.Array) else jax.device_put(np.zeros(x.shape, x.dtype),
                                                             x.sharding)


def read_ahead(out: str) -> None:
    """Start reading the newest checkpoint in ``out`` into host memory in a background
    thread, so that a resume's disk reads overlap what it does before it restores (building
    the env and the programs); :func:`load` takes that read (or its error) instead of
    reading again. The carry is then held whole in host memory until it is placed. Under
    ``jax.distributed`` nothing is read ahead: each process reads its own part at load."""
    root = ckpt_dir(out)
    done = _checkpoints(root)
    if done and not jax.distributed.is_initialized():
        path = os.path.join(root, done[-1])
        pool = concurrent.futures.ThreadPoolExecutor(1)
        _ahead[root] = (path, pool.submit(_read_host, path))
        pool.shutdown(wait=False)  # the thread ends with its read


class _Unreadable(ValueError):
    """What :func:`_read` found wrong with a checkpoint."""


def _read(path: str, want: dict, ahead: concurrent.futures.Future | None = None) -> dict:
    """The leaves saved in ``path`` (as ``ahead``, a :func:`read_ahead`, read them, where
    given), checked against ``want`` (the same keys, shapes and dtypes, before reading:
    orbax would cast or reshape; the run axis may be padded otherwise, see :func:`_repad`)
    and against the checksum saved with them, so that a damaged checkpoint fails here rather
    than restoring a wrong carry (orbax checks its index, not the arrays' bytes). A
    checkpoint without a checksum (written by an flrjax before checksums) is checked for
    shapes and dtypes only."""
    tree, host = ahead.result() if ahead is not None else (_metadata(path), None)
    runs = _check_leaves({k: v for k, v in tree.items() if k != CHECKSUM}, want)
    if host is None:
        if runs is None:  # as the run holds it: straight onto its devices
            import orbax.checkpoint as ocp

            target = jax.tree.map(ocp.utils.to_shape_dtype_struct, want)
        else:  # padded otherwise: whole on the host, to pad again
            target = {k: np.empty((runs, *x.shape[1:]), x.dtype) for k, x in want.items()}
        if CHECKSUM in tree:
            target[CHECKSUM] = np.zeros(1, np.uint32)
        saved = _restore(path, target)
    elif runs is None:  # read on the host: onto the run's devices, in one transfer
        keys = list(want)
        saved = {CHECKSUM: host[CHECKSUM]} if CHECKSUM in host else {}
        saved.update(zip(keys, jax.device_put([host[k] for k in keys],
                                              [want[k].sharding for k in keys]), strict=True))
    else:
        saved = dict(host)
    checksum = saved.pop(CHECKSUM, None)
    _check_leaves(saved, want)
    if checksum is not None and not np.array_equal(checksum, _checksum(saved)):
        raise _Unreadable("its arrays do not match the checksum saved with them")
    return saved if runs is None else {k: _repad(x, want[k]) for k, x in saved.items()}


@contextlib.contextmanager
def _orbax_quiet():
    """orbax's log lines off: it logs what the caller reports, in a line of its own. (One
    read at a time: :func:`load` waits for a :func:`read_ahead` before reading another.)"""
    absl = logging.getLogger("absl")
    level = absl.level
    absl.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        absl.setLevel(level)


def _metadata(path: str) -> dict:
    """The tree of array metadata (shapes, dtypes) saved in ``path``."""
    import orbax.checkpoint as ocp

    with _orbax_quiet(), ocp.StandardCheckpointer() as ckptr:
        tree = ckptr.metadata(path).item_metadata
    if tree is None:
        raise _Unreadable("its metadata cannot be read")
    return tree


def _restore(path: str, target: dict) -> dict:
    """The arrays saved in ``path`` read into ``target``'s shapes and placement."""
    import orbax.checkpoint as ocp

    with _orbax_quiet(), ocp.StandardCheckpointer() as ckptr:
        return ckptr.restore(path, target)


def _read_host(path: str) -> tuple[dict, dict]:
    """(metadata tree, arrays) of ``path``, the arrays whole in host memory."""
    tree = _metadata(path)
    return tree, _restore(path, {k: np.empty(v.shape, v.dtype) for k, v in tree.items()})


def _check_leaves(saved: dict, want: dict) -> int | None:
    """Raise :class:`_Unreadable` unless ``saved`` has ``want``'s keys, shapes and dtypes,
    but perhaps another length of the run axis, the same in every leaf: that length, or
    None where it is ``want``'s."""
    if saved.keys() != want.keys():
        raise _Unreadable(f"it holds {len(saved)} arrays, the run's state {len(want)}")
    runs = {int(saved[k].shape[0]) for k in want} if want else set()
    other = runs - {int(x.shape[0]) for x in want.values()}
    for k, x in want.items():
        shape, dtype = tuple(saved[k].shape), np.dtype(saved[k].dtype)
        if len(runs) > 1 or shape[1:] != x.shape[1:] or dtype != x.dtype or (
                not other and shape != x.shape):
            raise _Unreadable(f"array {k} is {dtype}{list(shape)}, the run's {x.dtype}"
                             f"{list(x.shape)}")
    return other.pop() if other else None


def _repad(saved: np.ndarray, want: jax.Array) -> jax.Array:
    """A leaf saved with another padding of the run axis, as ``want`` holds it: its first
    rows (every real run's: they come first in both), then copies of the last row kept for
    the padding runs, placed with ``want``'s sharding (each process its own part)."""
    n = want.shape[0]
    kept = saved[:n]
    x = np.concatenate([kept, np.repeat(kept[-1:], n - len(kept), 0)])
    return jax.make_array_from_callback(x.shape, want.sharding, lambda idx: x[idx])


def _checksum(leaves: dict) -> np.ndarray:
    """A position-weighted sum of the leaves' words modulo 2**32, in leaf order, as
    ``uint32[1]``. Computed where the arrays live (on the accelerator for a saved carry), so a
    save copies the carry to the host once, for orbax, and not a second time for this."""
    keys, fold = _checksum_program(leaves)
    return np.asarray(fold([leaves[k] for k in keys])).reshape(1)


def _checksum_program(leaves: dict) -> tuple[list[str], Callable]:
    """(the leaves' keys in the order :func:`_fold` takes them, its program for them)."""
    keys = sorted(leaves, key=int)
    where = tuple((leaves[k].shape, np.dtype(leaves[k].dtype), _split(leaves[k])) for k in keys)
    return keys, _fold_program(where, tuple(int(k) for k in keys), launch_cache.directory())


def _split(x) -> jax.sharding.Sharding | None:
    """``x``'s sharding where it is split over several devices, else None (one device, or a
    host array)."""
    s = getattr(x, "sharding", None)
    return s if s is not None and len(s.device_set) > 1 else None


@functools.cache
def _fold_program(where: tuple, indices: tuple[int, ...], store: str | None):
    """:func:`_fold` of leaves shaped and split as ``where`` says: the program an earlier
    launch stored (:mod:`flrjax.launch_cache`; tracing a carry's hundreds of leaves takes
    seconds, which a resume would pay before its first chunk), else jitted here. One per
    process, ``store`` and shape: a run's every save calls the same."""
    del store  # in the key: a program stored elsewhere is another
    fold = functools.partial(_fold, indices=indices)
    if jax.process_count() == 1:
        shapes = [jax.ShapeDtypeStruct(shape, dtype, sharding=s) for shape, dtype, s in where]
        stored = launch_cache.program("checksum", fold, (shapes,), tag=repr(indices))
        if stored is not None:
            return stored
    return fold


@functools.partial(jax.jit, static_argnames="indices")
def _fold(xs: list, indices: tuple[int, ...]) -> jax.Array:
    total = jnp.zeros((), jnp.uint32)
    for x, i in zip(xs, indices, strict=True):
        total = _leaf_checksum(x, total, jnp.uint32(i))
    return total


def _leaf_checksum(x: jax.Array, total: jax.Array, index: jax.Array) -> jax.Array:
    """``total`` folded with one leaf's words: the sum of (word + 1) times an odd multiplier of
    its position, the leaf's index mixed in, so that a changed, moved or swapped word changes
    the result (uint32 arithmetic wraps, so the sum's order does not matter)."""
    if x.dtype == jnp.bool_ or x.dtype.itemsize == 1:
        words = x.astype(jnp.uint8).astype(jnp.uint32)
    elif x.dtype.itemsize == 2:
        words = jax.lax.bitcast_convert_type(x, jnp.uint16).astype(jnp.uint32)
    else:  # 4 bytes, or 8 as two words
        words = jax.lax.bitcast_convert_type(x, jnp.uint32)
    words = words.reshape(words.shape[0] if words.ndim else 1, -1)
    row = jnp.arange(words.shape[0], dtype=jnp.uint32)[:, None]
    col = jnp.arange(words.shape[1], dtype=jnp.uint32)[None, :]
    pos = row * jnp.uint32(words.shape[1]) + col + index * jnp.uint32(0x9E3779B9)
    weight = pos * jnp.uint32(2654435761) | jnp.uint32(1)
    return total * jnp.uint32(16777619) + jnp.sum((words + 1) * weight, dtype=jnp.uint32)


def _one_line(e: Exception) -> str:
    """``e`` as the first line of its message, cut to a readable length, after its type
    unless :class:`_Unreadable`."""
    msg = (str(e).strip().splitlines() or [""])[0]
    msg = msg if len(msg) <= 100 else msg[:97] + "..."
    if isinstance(e, _Unreadable):
        return msg
    return f"{type(e).__name__}: {msg}" if msg else type(e).__name__


class CheckpointWarning(UserWarning):
    """A checkpoint could not be read and an older one is restored instead."""


def restore(cfg: TrainConfig, template, fields: tuple[str, ...]
            ) -> tuple[int, object, list[dict]]:
    """(chunks done, carry, metric rows up to that checkpoint) of the run in ``cfg.out``, from
    its newest readable checkpoint (:func:`load`); metrics.csv is rewritten with those rows,
    in the columns ``fields``, so the chunks after the checkpoint re-run and append theirs.
    Under ``jax.distributed`` every process reads the rows and restores its part of the carry;
    process 0 rewrites metrics.csv once all have read it, whole or not at all (a new file put
    in its place), so that a stop meanwhile loses no row and a reader never sees it cut."""
    n_done, carry = load(cfg.out or "", template)
    path = os.path.join(cfg.out, "metrics.csv")
    point = sweep_points(cfg)[0]
    ints = {"step", "seed", "falls", *(k for k, v in point.items() if isinstance(v, int))}
    strs = {k for k, v in point.items() if isinstance(v, str)}
    # a line that a kill cut short lacks fields (None); its chunk is not checkpointed either
    with open(path) as f:
        rows = [{k: (v if k in strs else int(v) if k in ints else float(v))
                 for k, v in r.items()} for r in csv.DictReader(f)
                if None not in r and None not in r.values()]
    rows = [r for r in rows if r["step"] <= n_done * cfg.steps_per_chunk]
    distributed.barrier("flrjax-metrics-read")
    if not distributed.is_main():
        return n_done, carry, rows
    with launch_cache.write_whole(path, "w", newline="") as f:
        w = csv.DictWriter(f, fields)
        w.writeheader()
        w.writerows(rows)
    return n_done, carry, rows
