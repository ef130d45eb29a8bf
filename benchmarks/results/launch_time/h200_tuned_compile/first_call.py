"""The trainer, each stored program's first call compared with its prefetch (shape, dtype, weak
type, sharding per leaf). Run as (one H200, `9af136f`; `weak_carry_9af136f.txt` holds its
log's lines with DIAG, jit_call', XLA compile seconds and the first chunk)::

    JAX_COMPILATION_CACHE_DIR=/tmp/cx JAX_EXPLAIN_CACHE_MISSES=1 JAX_LOG_COMPILES=1 \\
        python first_call.py --env ant3leg --seeds 5 --steps 76800 --checkpoint-every 0 --out R
"""
import sys

import jax

from flrjax import launch_cache
from flrjax.cli import main

pre, seen = {}, set()


def desc(x):
    return (tuple(x.shape), str(x.dtype), getattr(x, "weak_type", None),
            str(getattr(x, "sharding", None)))


def odd_layout(x):
    layout = getattr(getattr(x, "format", None), "layout", None)
    m2m = getattr(layout, "major_to_minor", None)
    return m2m is not None and tuple(m2m) != tuple(range(len(x.shape)))


orig_prefetch, orig_call = launch_cache.Stored.prefetch, launch_cache.Stored.__call__


def prefetch(self, *args):
    pre[id(self)] = [desc(leaf) for leaf in jax.tree.leaves(args)]
    return orig_prefetch(self, *args)


def call(self, *args):
    if id(self) in pre and id(self) not in seen:
        seen.add(id(self))
        now = [desc(leaf) for leaf in jax.tree.leaves(args)]
        pairs = enumerate(zip(pre[id(self)], now, strict=True))
        diffs = [(i, a, b) for i, (a, b) in pairs if a != b]
        print(f"DIAG call vs prefetch: {len(now)} leaves (prefetch {len(pre[id(self)])}), "
              f"{len(diffs)} differ", file=sys.stderr, flush=True)
        odd = [(i, leaf.shape, leaf.format.layout) for i, leaf in
               enumerate(jax.tree.leaves(args)) if odd_layout(leaf)]
        print(f"DIAG non-default layouts in the call: {len(odd)}", odd[:4], file=sys.stderr,
              flush=True)
        for d in diffs[:6]:
            print("DIAG", d, file=sys.stderr, flush=True)
    return orig_call(self, *args)


launch_cache.Stored.prefetch, launch_cache.Stored.__call__ = prefetch, call
main()
