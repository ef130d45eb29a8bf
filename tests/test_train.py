"""``flrjax.train``, the entry point."""





def test_importing_flrjax_prints_nothing():
    """MJX prints "Failed to import warp" twice when NVIDIA Warp is absent; flrjax drops it."""
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-c", "import flrjax.train"], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0 and res.stdout == "" and "warp" not in res.stderr, res
