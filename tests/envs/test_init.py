"""flrjax.envs' registry module: importing it changes nothing outside the process."""

import os
import subprocess
import sys


def test_importing_the_envs_leaves_mujoco_gl_to_the_user():
    """Programs started from a process that imported flrjax.envs (run_grid's, one per GPU)
    inherit its environment: a GL backend chosen there (EGL) would fail their import of MuJoCo
    on a machine without that library, so importing leaves MUJOCO_GL unset."""
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY")}
    out = subprocess.run(
        [sys.executable, "-c", "import os, flrjax.envs; print(os.environ.get('MUJOCO_GL'))"],
        env=env, capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "None"
