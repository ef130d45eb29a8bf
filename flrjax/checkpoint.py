"""A run's checkpoints: the whole carry (orbax) in ``OUT/checkpoints``, the last two kept,
and the restore that continues a run as if uninterrupted."""

from __future__ import annotations

import csv
import os
import re
import shutil

import jax

from flrjax.config import ConfigError, TrainConfig, sweep_points


def ckpt_dir(out: str) -> str:
    return os.path.abspath(os.path.join(out, "checkpoints"))


def _checkpoints(root: str) -> list[str]:
    """The finished checkpoints in ``root``, oldest first. A write that was killed leaves an
    orbax temporary directory (``chunk_000003.orbax-checkpoint-tmp-...``): not one of them."""
    if not os.path.isdir(root):
        return []
    return sorted(d for d in os.listdir(root) if re.fullmatch(r"chunk_\d{6}", d))


def has_checkpoint(out: str) -> bool:
    """Whether the run directory ``out`` holds a finished checkpoint to ``--resume`` from."""
    return bool(_checkpoints(ckpt_dir(out)))


def _nonempty_leaves(carry) -> dict:
    """The carry's leaves by index, without the zero-size ones (orbax refuses them; MJX's
    ``Data`` has some, e.g. ``act`` of a model without actuator state). Restoring takes those
    from the template, where they are just as empty."""
    return {str(i): x for i, x in enumerate(jax.tree.leaves(carry)) if x.size}


def save(out: str, n_done: int, carry) -> None:
    """Checkpoint the carry after ``n_done`` chunks; orbax writes to a temporary directory and
    renames it, so a crash mid-write leaves the previous checkpoint whole. Keeps the last two."""
    import orbax.checkpoint as ocp

    root = ckpt_dir(out)
    with ocp.StandardCheckpointer() as ckptr:
        ckptr.save(os.path.join(root, f"chunk_{n_done:06d}"), _nonempty_leaves(carry))
        ckptr.wait_until_finished()
    for old in _checkpoints(root)[:-2]:
        shutil.rmtree(os.path.join(root, old))


def restore(cfg: TrainConfig, template, fields: tuple[str, ...]
            ) -> tuple[int, object, list[dict]]:
    """(chunks done, carry, metric rows up to that checkpoint) of the run in ``cfg.out``;
    metrics.csv is rewritten with those rows, in the columns ``fields``."""
    import orbax.checkpoint as ocp

    root = ckpt_dir(cfg.out or "")
    done = _checkpoints(root)
    if not done:
        raise ConfigError(f"--resume: no checkpoint in {root}")
    n_done = int(done[-1].split("_")[1])
    target = jax.tree.map(ocp.utils.to_shape_dtype_struct, _nonempty_leaves(template))
    with ocp.StandardCheckpointer() as ckptr:
        saved = ckptr.restore(os.path.join(root, done[-1]), target)
    leaves, treedef = jax.tree.flatten(template)
    carry = jax.tree.unflatten(treedef, [saved.get(str(i), x) for i, x in enumerate(leaves)])
    path = os.path.join(cfg.out, "metrics.csv")
    point = sweep_points(cfg)[0]
    ints = {"step", "seed", "falls", *(k for k, v in point.items() if isinstance(v, int))}
    strs = {k for k, v in point.items() if isinstance(v, str)}
    with open(path) as f:
        rows = [{k: (v if k in strs else int(v) if k in ints else float(v))
                 for k, v in r.items()} for r in csv.DictReader(f)]
    rows = [r for r in rows if r["step"] <= n_done * cfg.steps_per_chunk]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fields)
        w.writeheader()
        w.writerows(rows)
    return n_done, carry, rows
