"""``flrjax.train``, the entry point."""

import subprocess
import sys


def test_importing_flrjax_prints_nothing_and_starts_nothing():
    """MJX prints "Failed to import warp" twice when NVIDIA Warp is absent; flrjax drops it.
    Only the command line starts JAX's backend early (below), not an import."""
    code = ("import threading, flrjax.train; "
            "assert 'flrjax-backend' not in [t.name for t in threading.enumerate()]")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0 and res.stdout == "" and "warp" not in res.stderr, res


ENTRY = """
import runpy, sys
import flrjax.cli, flrjax.distributed
calls = []
flrjax.distributed.start_backend = lambda argv: calls.append(("backend", list(argv)))
flrjax.cli.main = lambda argv=None: calls.append(("main", argv))
sys.argv = ["flrjax.train", "--env", "point4leg"]
runpy.run_module("flrjax.train", run_name="__main__")
print(calls)
"""


def test_the_command_line_starts_the_backend_before_it_runs():
    """``python -m flrjax.train`` hands its flags to ``distributed.start_backend`` (which
    decides whether a thread may start JAX's backend while the trainer imports) before
    ``main``."""
    res = subprocess.run([sys.executable, "-c", ENTRY], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[('backend', ['--env', 'point4leg']), ('main', None)]"
