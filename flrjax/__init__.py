"""flrjax: hierarchical goal-conditioned RL with the forward-looking reward, in JAX/MJX."""

import contextlib
import io
import sys


def _command_line() -> list[str] | None:
    """The flags of ``python -m flrjax.train`` while it imports this package (the interpreter
    has not yet put the module's path in ``sys.argv[0]``), else None."""
    orig = getattr(sys, "orig_argv", [])
    if sys.argv[:1] != ["-m"] or "-m" not in orig:
        return None
    at = orig.index("-m")
    return sys.argv[1:] if orig[at + 1:at + 2] == ["flrjax.train"] else None


def _import_mjx_quietly() -> None:
    """Import MJX with its two "Failed to import warp" lines dropped: MJX prints them to stdout
    whenever the optional NVIDIA Warp backend is absent, which flrjax never uses. On the
    command line JAX's backend starts first, in a thread, so that the device's start overlaps
    the imports (:func:`flrjax.distributed.start_backend`)."""
    with contextlib.redirect_stdout(io.StringIO()):
        argv = _command_line()
        if argv is not None:
            from flrjax.distributed import start_backend

            start_backend(argv)
        import mujoco.mjx  # noqa: F401


_import_mjx_quietly()

__version__ = "0.1.0"
