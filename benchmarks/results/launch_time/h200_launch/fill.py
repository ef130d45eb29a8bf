"""``python fill.py RUN [--uncompressed]``: RUN's newest checkpoint with its replay-sized leaves
(a million elements or more) filled with noise, so that it holds a full buffer's bytes, its
checksum kept valid. With ``--uncompressed``, also a copy of RUN in ``RUN_U`` whose checkpoint
is written without zstd."""
import logging
import os
import shutil
import sys

import numpy as np
import orbax.checkpoint as ocp

from flrjax import checkpoint as ck

logging.getLogger("absl").setLevel(logging.ERROR)
run = sys.argv[1]
root = ck.ckpt_dir(run)
name = ck._checkpoints(root)[-1]
path = os.path.join(root, name)
with ocp.StandardCheckpointer() as c:
    meta = c.metadata(path).item_metadata
    d = c.restore(path, {k: np.empty(v.shape, v.dtype) for k, v in meta.items()})
rng = np.random.default_rng(0)
d.pop(ck.CHECKSUM)
big = 0
for k, x in d.items():
    if x.size >= 10**6:
        big += x.nbytes
        d[k] = (rng.random(x.shape) < 0.5) if x.dtype == np.bool_ else \
            rng.standard_normal(x.shape, dtype=np.float32).astype(x.dtype)
print("filled", big / 2**30, "GiB of", sum(x.nbytes for x in d.values()) / 2**30)
d[ck.CHECKSUM] = ck._checksum(d)
shutil.rmtree(path)
with ocp.StandardCheckpointer() as c:
    c.save(path, d)
if "--uncompressed" in sys.argv:
    u = run.rstrip("/") + "_U"
    shutil.rmtree(u, ignore_errors=True)
    shutil.copytree(run, u)
    upath = os.path.join(ck.ckpt_dir(u), name)
    shutil.rmtree(upath)
    cu = ocp.Checkpointer(ocp.PyTreeCheckpointHandler(use_compression=False))
    cu.save(upath, d)
    cu.close()
    os.system(f"du -sh {path} {upath}")
else:
    os.system(f"du -sh {path}")
