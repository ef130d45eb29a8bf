"""One persistent JAX compilation cache for the whole test session.

Many tests (and the notebook kernels and subprocesses they start, which inherit the
environment) compile the same tiny training programs; sharing compiled executables across
processes cuts CI time by minutes (the notebook and figure tests: 301 s -> 177 s on 2 cores).
The cache lives in a temporary directory removed at the end, unless one was given.
"""

import os
import shutil
import tempfile

_OWN_CACHE = "JAX_COMPILATION_CACHE_DIR" not in os.environ
CACHE = os.environ.setdefault("JAX_COMPILATION_CACHE_DIR",
                              tempfile.mkdtemp(prefix="flrjax-test-jit-cache-"))
# Never a traced program stored by another test or process (flrjax.launch_cache): tests patch
# functions in memory, which the programs' keys cannot see. tests/test_launch_cache.py turns
# it on for itself.
os.environ["FLRJAX_PROGRAM_CACHE"] = "0"

import jax  # noqa: E402

jax.config.update("jax_compilation_cache_dir", CACHE)


def pytest_sessionfinish(session, exitstatus):
    if _OWN_CACHE:
        shutil.rmtree(CACHE, ignore_errors=True)
