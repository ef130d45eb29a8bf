"""Session-wide settings for the CPU test suite: one persistent JAX compilation cache and a
cheap XLA backend.

Many tests (and the notebook kernels and subprocesses they start, which inherit the
environment) compile the same tiny training programs; sharing compiled executables across
processes saves recompiling them. The cache lives in a temporary directory removed at the end,
unless one was given.

The tests' programs are tiny and compiled far more often than they run long, so XLA's CPU
backend (LLVM) compiles them without its optimisation passes
(``--xla_backend_optimization_level=0``), and emits fusions with its older emitters instead of
the MLIR fusion emitters (``--xla_cpu_use_fusion_emitters=false``), which are slower to compile.
This leaves XLA's graph passes and every program's meaning as they are; only the
generated machine code differs (less tuned, float rounding may differ in the last bits). A
setting of either already given in XLA_FLAGS is kept.
"""

import os
import shutil
import tempfile

import pytest

_OWN_CACHE = "JAX_COMPILATION_CACHE_DIR" not in os.environ
CACHE = os.environ.setdefault("JAX_COMPILATION_CACHE_DIR",
                              tempfile.mkdtemp(prefix="flrjax-test-jit-cache-"))
# Never a traced program stored by another test or process (flrjax.launch_cache): tests patch
# functions in memory, which the programs' keys cannot see. tests/test_launch_cache.py turns
# it on for itself.
os.environ["FLRJAX_PROGRAM_CACHE"] = "0"
for _flag, _value in (("xla_backend_optimization_level", "0"),
                      ("xla_cpu_use_fusion_emitters", "false")):
    if _flag not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"--{_flag}={_value} {os.environ.get('XLA_FLAGS', '')}".strip()

import jax  # noqa: E402

jax.config.update("jax_compilation_cache_dir", CACHE)


def pytest_sessionfinish(session, exitstatus):
    if _OWN_CACHE:
        for path in (CACHE, CACHE + "-programs"):  # the latter: see launch_env
            shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope="session")
def launch_env() -> dict[str, str]:
    """The environment of a trainer or benchmark launched in a subprocess as a user launches
    it: its traced programs kept between launches (``flrjax.launch_cache``), beside the
    session's compilation cache. Only such processes, which patch nothing, read and write
    that store; the tests' own process never does."""
    return {k: v for k, v in os.environ.items() if k != "FLRJAX_PROGRAM_CACHE"}
