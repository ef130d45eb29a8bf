"""flrjax: hierarchical goal-conditioned RL with the forward-looking reward, in JAX/MJX."""

import contextlib
import io


def _import_mjx_quietly() -> None:
    """Import MJX with its two "Failed to import warp" lines dropped: MJX prints them to stdout
    whenever the optional NVIDIA Warp backend is absent, which flrjax never uses."""
    with contextlib.redirect_stdout(io.StringIO()):
        import mujoco.mjx  # noqa: F401


_import_mjx_quietly()

__version__ = "0.1.0"
