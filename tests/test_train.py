"""``flrjax.train``, the entry point."""

import subprocess
import sys

import pytest

import flrjax

STARTED = """
import sys, threading
{argv}
import flrjax
for t in threading.enumerate():
    if t.name == "flrjax-backend":
        t.join()
from jax._src import xla_bridge
print(xla_bridge.backends_are_initialized())
"""


def test_importing_flrjax_prints_nothing():
    """MJX prints "Failed to import warp" twice when NVIDIA Warp is absent; flrjax drops it."""
    res = subprocess.run([sys.executable, "-c", "import flrjax.train"], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0 and res.stdout == "" and "warp" not in res.stderr, res


@pytest.mark.parametrize("command_line", [True, False])
def test_only_the_command_line_starts_the_backend_while_it_imports(command_line):
    """Under ``python -m flrjax.train`` (``sys.argv`` and ``sys.orig_argv`` as the interpreter
    has them while it imports the package) importing flrjax starts JAX's backend in a thread,
    so that the device's start overlaps the imports; a plain import starts nothing."""
    argv = ("sys.argv = ['-m', '--env', 'point4leg']; sys.orig_argv = [sys.executable, "
            "'-m', 'flrjax.train', '--env', 'point4leg']") if command_line else ""
    res = subprocess.run([sys.executable, "-c", STARTED.format(argv=argv)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == str(command_line)


@pytest.mark.parametrize("argv,orig,flags", [
    (["-m", "--env", "x"], ["python", "-m", "flrjax.train", "--env", "x"], ["--env", "x"]),
    (["-m"], ["python", "-X", "importtime", "-m", "flrjax.train"], []),
    (["-m", "--x"], ["python", "-m", "other.module", "--x"], None),
    (["run.py", "--env", "x"], ["python", "run.py", "--env", "x"], None),
    (["-c"], ["python", "-c", "import flrjax"], None),
])
def test_the_command_line_is_told_from_other_imports(monkeypatch, argv, orig, flags):
    monkeypatch.setattr(sys, "argv", argv)
    monkeypatch.setattr(sys, "orig_argv", orig)
    assert flrjax._command_line() == flags
