"""Traced programs kept between launches, so that a second launch of a config skips tracing.

On a warm launch the compilation cache already spares the trainer's compile, but tracing and
lowering the chunk (a vmap of nested scans over MJX steps and every learner) are still paid
again. Here the trainer's init, chunk and evaluation are stored as ``jax.export`` artifacts
on their first launch, and later launches call the stored programs: loading one and lowering
its call is much cheaper than tracing it, and the compile then comes from the compilation
cache.

A stored program is used only where everything that shapes its trace is the same: the
config's shape fields (:func:`flrjax.runner._shape_key`), the arguments' shapes and dtypes,
the source of every module of flrjax, the versions of jax, jaxlib, MuJoCo and the other
packages a trace reads, the JAX settings that change a trace, and the backend and device
kind. Anything else gives another key, hence a new export. Off unless :func:`enable` is called
(the trainer's command line does, with its compilation cache: :func:`enable_compile_cache`),
and always off with ``FLRJAX_PROGRAM_CACHE=0``: a test that patches a function in memory must
never meet a program stored by another process. A program split over several devices of one
process is stored with its shardings (the device count enters the key through them); under
``jax.distributed`` the programs are traced as before.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import hashlib
import importlib.metadata
import os
import pickle
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import jax

#: The environment variable that turns stored programs off whatever :func:`enable` says.
SWITCH = "FLRJAX_PROGRAM_CACHE"
#: Custom calls of our programs that ``jax.export`` does not allow by itself: the Pallas
#: kernels (gc_td3.fused_value) lowered by Triton on a GPU.
CUSTOM_CALLS = ("__gpu$xla.gpu.triton",)
#: Packages whose version can change a trace (MuJoCo's compiled model enters it as constants).
PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "brax", "flax", "optax", "chex", "numpy")
#: JAX settings that change what a function traces to.
TRACE_SETTINGS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_default_prng_impl",
                  "jax_threefry_partitionable", "jax_numpy_rank_promotion")

#: The store's size limit: past it, the programs used least recently are deleted (each config
#: and source version adds its own programs).
MAX_BYTES = 512 * 2**20

_dir: str | None = None
#: The background compiles :meth:`Stored.prefetch` started (:func:`_settle` waits for them).
_compiling: list[threading.Thread] = []


def enable(path: str | None) -> None:
    """Store and load programs in ``path`` (None: off)."""
    global _dir
    _dir = path


def default_compile_cache() -> str:
    """Where compiled programs persist between runs: ``$JAX_COMPILATION_CACHE_DIR`` if set,
    else ``flrjax/jax`` in the user's cache directory (``$XDG_CACHE_HOME`` or ``~/.cache``)."""
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return os.environ["JAX_COMPILATION_CACHE_DIR"]
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(root, "flrjax", "jax")


def enable_compile_cache(path: str | None) -> None:
    """Keep compiled programs in ``path`` (None: the cache stays as JAX has it), so that a
    second launch of the same config loads its chunk instead of compiling it again, and the
    traced programs beside it in ``path-programs`` (:mod:`flrjax.launch_cache`), so that it
    does not trace them again either. Every program is kept, the small ones too (the check
    for non-finite parameters, the checkpoint's checksum, the keys' arithmetic): loading one
    is quicker than compiling it, and a launch compiles many."""
    enable(None if path is None else path.rstrip(os.sep) + "-programs")
    if path is None:
        return
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def directory() -> str | None:
    """Where programs are stored now, or None when off."""
    return None if os.environ.get(SWITCH, "1") == "0" else _dir


@functools.cache
def source_hash() -> str:
    """sha256 of every ``.py`` file of the flrjax package, with its path."""
    root = os.path.dirname(os.path.abspath(__file__))
    h = hashlib.sha256()
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            h.update(os.path.relpath(path, root).encode())
            with open(path, "rb") as f:
                h.update(f.read())
    return h.hexdigest()


def key(name: str, tag: str, args: Any) -> str:
    """The stored program's name: everything that shapes the trace of ``name`` on ``args``
    (a tuple of pytrees of ``ShapeDtypeStruct``) for a config whose shape fields print as
    ``tag``. The same in every process (tests/test_launch_cache.py)."""
    device = jax.devices()[0]
    # leaves, not the tree's printout: static fields (MJX's) print with memory addresses
    parts = [name, tag, str([[(x.shape, str(x.dtype), _where(x)) for x in jax.tree.leaves(a)]
                             for a in args]), source_hash(),
             *(f"{p}={_version(p)}" for p in PACKAGES), device.platform, device.device_kind,
             *(f"{s}={getattr(jax.config, s, None)}" for s in TRACE_SETTINGS)]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


def _where(x: Any) -> str:
    """How an argument is split over devices (its sharding: the mesh's size and the spec;
    "" where it names none, one device)."""
    s = getattr(x, "sharding", None)
    return "" if s is None else repr(s)


def _version(package: str) -> str | None:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None


class Stored:
    """A stored program called like the jitted function it was exported from: pytrees in,
    pytrees out, the same donated arguments."""

    def __init__(self, exported: jax.export.Exported, out_tree: Any,
                 donate_argnums: tuple[int, ...], compiler_options: dict | None = None):
        self.exported, self.out_tree = exported, out_tree
        self._call = jax.jit(exported.call, donate_argnums=donate_argnums,
                             compiler_options=compiler_options)

    def prefetch(self, *args) -> None:
        """Compile (on a warm launch: load from the compilation cache) for arguments shaped
        as ``args`` in a background thread, so that the load overlaps what the caller does
        before the first call (another program's load and run). JAX's in-memory caches give
        the call that executable, also while the compile is in flight (one compile)."""
        thread = threading.Thread(target=lambda: self.lower(*args).compile(), daemon=True)
        thread.start()
        _compiling.append(thread)

    def __call__(self, *args):
        return jax.tree.unflatten(self.out_tree, self._call(*_flat(args)))

    def lower(self, *args):
        return self._call.lower(*_flat(args))

    def eval_shape(self, *args):
        """The outputs' shapes, read from the stored program (nothing is traced)."""
        del args
        return jax.tree.unflatten(self.out_tree, [jax.ShapeDtypeStruct(a.shape, a.dtype)
                                                  for a in self.exported.out_avals])


@atexit.register
def _settle() -> None:
    """At exit, wait for the background compiles still running: a process that ends while
    XLA compiles in one of its threads aborts (C++ ``terminate``) instead of exiting with its
    own code and message, e.g. a one-line error raised before the first chunk."""
    while _compiling:
        _compiling.pop().join()


def _flat(args: Sequence[Any]) -> list[list[Any]]:
    """Each positional argument as the list of its leaves (what the export's program takes:
    plain lists, which ``jax.export`` can serialize, unlike our dataclasses)."""
    return [jax.tree.leaves(a) for a in args]


def program(name: str, fn: Callable, args: tuple, tag: str,
            donate_argnums: tuple[int, ...] = (), compiler_options: dict | None = None,
            out_shardings: Any = None) -> Stored | None:
    """``fn`` (a function of pytrees; if jitted, without compiler options, which a nested jit
    cannot take) for arguments shaped as ``args`` (ShapeDtypeStructs, with their shardings
    where split over devices; every output split as ``out_shardings``): the stored program if
    there is one, else ``fn`` exported now and stored; either compiled with
    ``compiler_options`` (XLA's: they do not change the trace). None when
    programs are not stored (off) or ``fn`` cannot be exported or stored: the caller then uses
    ``fn`` itself. For programs of one process (the caller checks)."""
    root = directory()
    if root is None:
        return None
    path = os.path.join(root, key(name, tag, args) + ".bin")
    if os.path.exists(path):
        try:
            with open(path, "rb") as f:
                blob, out_tree = pickle.load(f)
            with contextlib.suppress(OSError):  # used now: the last to go when pruned
                os.utime(path)
            return Stored(jax.export.deserialize(bytearray(blob)), out_tree, donate_argnums,
                          compiler_options)
        except Exception as e:  # a damaged or foreign file: export again below
            warnings.warn(f"stored program {path} unreadable ({e}); tracing {name} again",
                          stacklevel=2)
    trees = [jax.tree.structure(a) for a in args]
    out_tree = []

    def flat(*leaves):
        out = fn(*(jax.tree.unflatten(t, x) for t, x in zip(trees, leaves, strict=True)))
        out_tree.append(jax.tree.structure(out))
        return jax.tree.leaves(out)

    try:
        exported = jax.export.export(
            jax.jit(flat, donate_argnums=donate_argnums, out_shardings=out_shardings),
            disabled_checks=[jax.export.DisabledSafetyCheck.custom_call(c)
                             for c in CUSTOM_CALLS])(*_flat(args))
        blob = pickle.dumps((exported.serialize(), out_tree[0]))
    except Exception as e:  # e.g. a custom call or pytree jax.export cannot take
        warnings.warn(f"{name} cannot be stored for the next launch ({e})", stacklevel=2)
        return None
    os.makedirs(root, exist_ok=True)
    with write_whole(path, "wb") as f:
        f.write(blob)
    prune(root, MAX_BYTES, keep=path)
    return Stored(exported, out_tree[0], donate_argnums, compiler_options)


@contextlib.contextmanager
def write_whole(path: str, mode: str = "w", **kw):
    """A file opened for writing in place of ``path``: a new file that replaces ``path`` when
    the block ends, or is removed if it raises, so that a reader (or a stop meanwhile) sees
    the old file or the new one, never one cut short."""
    tmp = f"{path}.{os.getpid()}"
    try:
        with open(tmp, mode, **kw) as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise


#: JAX's monitoring events (jax/_src/compiler.py, compilation_cache.py): a program taken from
#: the compilation cache, and one compiled for want of it.
CACHE_EVENTS = {"/jax/compilation_cache/cache_hits": "from the compilation cache",
                "/jax/compilation_cache/cache_misses": "compiled"}
#: JAX's monitoring durations (jax/_src/dispatch.py): a jit's trace, its lowering to MLIR, and
#: XLA's compile (or the compilation cache's load) of it.
STAGES = {"/jax/core/compile/jaxpr_trace_duration": "tracing",
          "/jax/core/compile/jaxpr_to_mlir_module_duration": "lowering",
          "/jax/core/compile/backend_compile_duration": "compiling or loading"}
#: JAX's monitoring duration (jax/_src/compiler.py) of a program's read from the compilation
#: cache (the file, its decompression and XLA's load of the executable): part of "compiling
#: or loading", the rest of which is the cache key's hashing of the program, or its compile.
CACHE_READ = "/jax/compilation_cache/cache_retrieval_time_sec"


class CompileLog:
    """Where a launch's time to its first chunk went: seconds of tracing, lowering and
    compiling, and programs from the compilation cache or compiled, as JAX's monitoring events
    report them while the log listens (:func:`compile_log`), also those of a program loaded in
    a background thread (:meth:`Stored.prefetch`)."""

    def __init__(self):
        self.seconds = dict.fromkeys(STAGES.values(), 0.0)
        self.cache_read = 0.0  # seconds of "compiling or loading" reading the cache
        self.programs = dict.fromkeys(CACHE_EVENTS.values(), 0)
        self.spans: list[tuple[float, float]] = []  # (start, end) on time.perf_counter

    def event(self, event: str, **_) -> None:
        if event in CACHE_EVENTS:
            self.programs[CACHE_EVENTS[event]] += 1

    def duration(self, event: str, secs: float, **_) -> None:
        if event == CACHE_READ:
            self.cache_read += secs
        if event in STAGES:
            self.seconds[STAGES[event]] += secs
            end = time.perf_counter()  # JAX reports a stage as it ends
            self.spans.append((end - secs, end))

    def total(self) -> float:
        """Seconds of tracing, lowering and compiling or loading so far."""
        return sum(self.seconds.values())

    def within(self, start: float, end: float) -> float:
        """Seconds between ``start`` and ``end`` (``time.perf_counter``) during which some
        stage ran: what a call waited for, not a background load's seconds before it, and
        programs loaded side by side counted once."""
        busy, reach = 0.0, start
        for a, b in sorted(self.spans):
            a, b = max(a, reach), min(b, end)
            if b > a:
                busy, reach = busy + b - a, b
        return busy

    def summary(self) -> str:
        """e.g. "tracing 1.1 s, lowering 0.9 s, compiling or loading 3.5 s (2.9 s of it reading
        the compilation cache); programs: 12 from the compilation cache, 0 compiled"."""
        read = (f" ({self.cache_read:.1f} s of it reading the compilation cache)"
                if self.programs[CACHE_EVENTS["/jax/compilation_cache/cache_hits"]] else "")
        return (", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items()) + read
                + "; programs: " + ", ".join(f"{v} {k}" for k, v in self.programs.items()))


@contextlib.contextmanager
def compile_log():
    """A :class:`CompileLog` listening to this process's compiles inside the block."""
    log = CompileLog()
    jax.monitoring.register_event_listener(log.event)
    jax.monitoring.register_event_duration_secs_listener(log.duration)
    try:
        yield log
    finally:
        jax.monitoring.unregister_event_listener(log.event)
        jax.monitoring.unregister_event_duration_listener(log.duration)


def prune(root: str, max_bytes: int, keep: str | None = None) -> list[str]:
    """Delete the programs of ``root`` used least recently (oldest modification time: a load
    touches its file) until the rest take at most ``max_bytes``; never ``keep``. Returns the
    deleted paths. Another process may delete the same file first: that is no error."""
    files = []
    for name in os.listdir(root):
        path = os.path.join(root, name)
        if name.endswith(".bin") and path != keep:
            try:
                st = os.stat(path)
            except FileNotFoundError:
                continue
            files.append((st.st_mtime, st.st_size, path))
    total = sum(size for _, size, _ in files) + (os.path.getsize(keep) if keep else 0)
    deleted = []
    for _, size, path in sorted(files):
        if total <= max_bytes:
            break
        try:
            os.remove(path)
        except FileNotFoundError:
            pass
        total -= size
        deleted.append(path)
    return deleted

