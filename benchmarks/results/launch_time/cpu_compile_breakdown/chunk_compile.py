"""Seconds to trace and lower, then to compile, one config's training chunk (nothing run).

    python benchmarks/results/launch_time/cpu_compile_breakdown/chunk_compile.py "TRAINER FLAGS"

Made for target 2a's CPU breakdown (README.md beside it); XLA_FLAGS applies as usual."""

import sys
import tempfile
import time

import jax
import numpy as np

from flrjax import cli, runner

flags = sys.argv[1]
cfg = cli.parse_cli([*flags.split(), "--out", tempfile.mkdtemp()]).cfg
init, chunk, _ = runner.build(cfg)
carry = init.eval_shape(jax.ShapeDtypeStruct((cfg.runs, 2), np.uint32))
t = time.perf_counter()
lowered = chunk.lower(carry, np.int32(0))
traced = time.perf_counter() - t
t = time.perf_counter()
lowered.compile()
print(f"{flags}: trace and lower {traced:.1f} s, compile {time.perf_counter() - t:.1f} s")
