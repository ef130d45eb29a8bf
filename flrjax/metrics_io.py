"""What a run leaves in its directory: config.json with its provenance (versions, git commit,
command), metrics.csv, and for a person to look at its summary, ``curves.png`` and TensorBoard
events, from the trainer's metric rows (read, tabled and named by :mod:`flrjax.analysis`).

Rows come as :func:`flrjax.runner.train` returns them: one per run (seed x sweep point) per
evaluation, run ``r`` being seed ``r % seeds`` of sweep point ``r // seeds``.
"""

from __future__ import annotations

import csv
import json
import os
import shlex
import subprocess
import sys
import textwrap

import jax
import numpy as np

from flrjax import algos
from flrjax.analysis import (
    FALL_METRICS,
    can_fall,
    env_name,
    metric_label,
    plural,
    point_name,
    sample_std,
    table,
)
from flrjax.config import ConfigError, TrainConfig, algo_config, flags, make

#: Panels of ``curves.png``: metric, cumulative over evaluations.
CURVES = (("success_rate", False), ("falls", True), ("critic_loss", False))

def run_files(out: str) -> dict[str, str]:
    """The files of :data:`RUN_FILES`, config.json and TensorBoard's event files that
    ``out`` holds, by name: what a run wrote there, not what else a user keeps beside it."""
    names = [n for n in sorted(os.listdir(out))
             if n in ("config.json", *RUN_FILES) or n.startswith("events.out.tfevents.")]
    return {n: os.path.join(out, n) for n in names}


def summarize(algo: str, points: list[dict], seeds: int, steps: int, rows: list[dict],
              out: str | None) -> dict:
    """Per sweep point: success at the last evaluation (mean over seeds, and with several
    seeds their sample std) and at the best one (its seed mean and the first step it was
    reached), falls in the last evaluation and in all of them (per seed, mean over seeds); the
    run's steps, wall time and files (:func:`run_files`)."""
    n = len(points)
    step = np.array([r["step"] for r in rows[::n * seeds]])
    success, falls = (table(rows, k, n, seeds) for k in ("success_rate", "falls"))
    best = success.mean(-1).argmax(0)
    spread = seeds > 1  # one seed has no spread to report
    summary = {
        "env_steps_per_seed": int(step[-1]), "of": steps, "seeds": seeds,
        "wall_time_s": float(rows[-1]["wall_time"]),
        **({"std": "sample standard deviation over seeds (ddof 1)"} if spread else {}),
        "points": [{
            "name": point_name(algo, pt), **pt,
            "success": {"mean": float(success[-1, i].mean()),
                        **({"std": float(sample_std(success[-1, i]))} if spread else {})},
            "best_success": {"mean": float(success[best[i], i].mean()),
                             "step": int(step[best[i]])},
            "falls_last_eval": float(falls[-1, i].mean()),
            "falls_total": float(falls[:, i].sum(0).mean()),
        } for i, pt in enumerate(points)],
    }
    if out:
        summary["files"] = run_files(out)
    return summary


def format_summary(s: dict) -> str:
    """The summary as the lines a run prints at its end (± only with several seeds)."""
    spread = s["seeds"] > 1
    lines = [f"{s['env_steps_per_seed']:,} of {s['of']:,} env steps per seed, "
             f"{plural(s['seeds'], 'seed')}, {s['wall_time_s'] / 60:.1f} min"]
    for p in s["points"]:
        success = f"{p['success']['mean']:.2f}" + (f" ± {p['success']['std']:.2f}" if spread
                                                   else "")
        lines.append(
            f"  {p['name']}: success {success} "
            f"(best {p['best_success']['mean']:.2f} at {p['best_success']['step']:,}); falls "
            f"{p['falls_last_eval']:.1f} in the last evaluation, {p['falls_total']:.0f} in all")
    if spread:
        lines.append("  (± is the sample std over seeds)")
    for name, path in s.get("files", {}).items():
        lines.append(f"  {name + ':':<14}{path}")
    return "\n".join(lines)


def plot_curves(algo: str, points: list[dict], seeds: int, rows: list[dict], path: str,
                env: str, steps: int | None = None) -> None:
    """``curves.png``: success, cumulative falls (not for the point mass, which cannot fall)
    and the low-level critic loss against env steps per seed, mean over seeds with (several
    seeds) a ± sample-std band (clipped to >= 0, success's to [0, 1]), one line per sweep
    point; a metric with no value in any row is left out. The title names the method and env
    as the paper does, and says where the run stopped if that is short of ``steps``."""
    from matplotlib.figure import Figure  # no pyplot: works without a display
    from matplotlib.ticker import FuncFormatter

    n = len(points)
    step = np.array([r["step"] for r in rows[::n * seeds]])
    panels = [(key, cumulative, t.cumsum(0) if cumulative else t)
              for key, cumulative in CURVES
              if key in rows[0] and (can_fall(env) or key not in FALL_METRICS)
              for t in [table(rows, key, n, seeds)] if np.isfinite(t).any()]
    fig = Figure(figsize=(4.2 * len(panels), 3.4))
    for ax, (key, cumulative, t) in zip(fig.subplots(1, len(panels), squeeze=False)[0],
                                        panels, strict=True):
        for i, pt in enumerate(points):
            with np.errstate(all="ignore"):
                m, s = np.nanmean(t[:, i], -1), sample_std(t[:, i])
            ax.plot(step, m, label=point_name(algo, pt), color=f"C{i % 10}")
            if seeds > 1:  # every panel's metric is >= 0, and success <= 1
                hi = 1 if key == "success_rate" else np.inf
                ax.fill_between(step, np.clip(m - s, 0, hi), np.clip(m + s, 0, hi), alpha=0.2,
                                color=f"C{i % 10}")
        ax.set_xlabel("env steps per seed")
        if step[-1] >= 100_000:  # 1.5M, not 1.5 under a 1e6 offset
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1e6:g}M" if v
                                                       else "0"))
        ax.set_ylabel(textwrap.fill(metric_label(key, cumulative), 36), fontsize=9)
        ax.grid(alpha=0.3)
    fig.axes[0].legend(fontsize=8)
    method = f"{point_name(algo, points[0])} on " if n == 1 else ""  # else in the legend
    spread = "; mean ± sample std over seeds" if seeds > 1 else ""
    stopped = (f"; stopped at {step[-1]:,} of {steps:,} env steps per seed"
               if steps is not None and step[-1] < steps else "")
    fig.suptitle(f"{method}{env_name(env)}, {plural(seeds, 'seed')}{spread}{stopped}",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


class TensorBoard:
    """TensorBoard event files beside metrics.csv: each metric's mean over seeds per sweep
    point, at each evaluation's env step (tensorboardX, installed with brax)."""

    def __init__(self, out: str, algo: str, points: list[dict], seeds: int):
        from tensorboardX import SummaryWriter

        self.writer = SummaryWriter(out)
        self.names = [point_name(algo, pt) for pt in points]
        self.seeds = seeds

    def write(self, step: int, rows: list[dict]) -> None:
        """One evaluation's rows (all runs)."""
        for i, name in enumerate(self.names):
            group = rows[i * self.seeds:(i + 1) * self.seeds]
            for key, value in group[0].items():
                if isinstance(value, float | int) and key not in ("step", "seed"):
                    with np.errstate(all="ignore"):
                        mean = float(np.nanmean([r[key] for r in group]))
                    self.writer.add_scalar(f"{name}/{key}", mean, step)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


def git_state() -> dict:
    """The flrjax checkout's commit and whether its tracked files are unchanged (None for
    both outside a git checkout, e.g. an installed wheel). ``$FLRJAX_GIT_COMMIT``, if set,
    is the commit instead, for code run from a copy of the tree whose ``.git`` is absent or
    not the code's (a tree synced to a cluster); ``$FLRJAX_GIT_CLEAN`` (``1`` or ``0``, from
    the copy's source) says whether that tree was clean (None, unknown, without it)."""
    if os.environ.get("FLRJAX_GIT_COMMIT"):
        clean = {"1": True, "0": False}.get(os.environ.get("FLRJAX_GIT_CLEAN", "").strip())
        return {"commit": os.environ["FLRJAX_GIT_COMMIT"], "clean": clean}
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=here, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return {"commit": None, "clean": None}
    return {"commit": head, "clean": not dirty.strip()}


def command_line(argv: list[str] | None = None) -> str:
    """The command this process runs as its user typed it: ``python -m flrjax.train ARGS``
    for a module run with ``-m`` (whose ``sys.argv[0]`` is the module's absolute path), else
    ``python SCRIPT ARGS``. ``argv``: ``sys.argv``."""
    argv = sys.argv if argv is None else argv
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None and spec.name:
        return shlex.join(["python", "-m", spec.name.removesuffix(".__main__"), *argv[1:]])
    return shlex.join(["python", *argv])


def provenance() -> dict:
    """What a benchmark's result file records of its origin: the command line
    (:func:`command_line`), and the commit (:func:`git_state`)."""
    return {"command": command_line(), **git_state()}


def write_json(path: str, obj: dict) -> None:
    """``obj`` as indented JSON at ``path``, its folder made if missing."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path, "w") as f:
        json.dump(obj, f, indent=1)


def package_versions() -> dict[str, str]:
    """Versions of Python and of the packages a run's numbers depend on."""
    from importlib import metadata

    out = {"python": sys.version.split()[0]}
    for name in ("flrjax", "jax", "jaxlib", "mujoco", "mujoco-mjx", "brax", "flax", "optax",
                 "numpy", "orbax-checkpoint"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


#: Fields newer than saved runs, left out of :func:`config_dict` while None (their default),
#: so a run that does not set them saves, and compares with old config.json files (resume,
#: run_grid's grid.json and --adopt), as before they existed.
_OMITTED_WHEN_NONE = ("flr_value_chunk", "flr_precision", "subgoal_test_precision",
                      "train_precision", "value_kernel")


def config_dict(cfg: TrainConfig) -> dict:
    """``cfg`` as config.json holds it: every flag of the run (the shared ones and its
    method's, :func:`flrjax.config.flags`; a sweep's tuples as lists), to compare with one."""
    d = json.loads(json.dumps(flags(cfg)))
    return {k: v for k, v in d.items() if not (k in _OMITTED_WHEN_NONE and v is None)}


#: Files a run writes into its directory (besides config.json): a directory holding any of
#: them without a config.json is someone else's, and is never written into.
RUN_FILES = ("metrics.csv", "checkpoints", "summary.json", "curves.png")


def check_out(cfg: TrainConfig, *, new_run: bool = True) -> None:
    """Refuse, with a :class:`ConfigError`, an ``--out`` that cannot take the run: a file, a
    path under a file, a directory this process cannot write, a run's files without their
    config.json, or (``new_run``) another run's config.json. The command line checks all but
    the last before anything starts (a script may continue a run by its ``--out``);
    :func:`prepare_out` checks all of them before a new run writes anything."""
    out = cfg.out
    if not out:
        return
    if os.path.exists(out) and not os.path.isdir(out):
        raise ConfigError(f"--out {out} is a file, not a directory")
    parent = os.path.abspath(out)
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if not os.path.isdir(parent):
        raise ConfigError(f"--out {out}: {parent} is a file, not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"--out {out}: {parent} is not writable")
    path = os.path.join(out, "config.json")
    if os.path.exists(path) and new_run:
        try:
            with open(path) as f:
                old = json.load(f).get("config", {})
        except (OSError, ValueError, AttributeError):
            old = {}
        diff = sorted(k for k, v in config_dict(cfg).items() if old.get(k) != v)
        raise ConfigError(f"--out {out} already holds a run"
                          + (f" with a different config ({', '.join(diff)})" if diff else "")
                          + "; choose another --out (or --resume it)")
    found = [f for f in RUN_FILES if os.path.exists(os.path.join(out, f))]
    if found and not os.path.exists(path):
        raise ConfigError(f"--out {out} holds {', '.join(found)} but no config.json; choose "
                          "another --out")


def resolved_settings(cfg: TrainConfig) -> dict:
    """The settings whose defaults depend on the device or the method, as this run computes
    with them (its flags leave them None; :attr:`flrjax.algos.Method.resolved`): e.g. the
    updates' matrix operands, eq. 5's candidate values' and subgoal testing's."""
    return algos.get(cfg.algo).resolved(algo_config(cfg))


def prepare_out(cfg: TrainConfig, fields: tuple[str, ...]) -> None:
    """Create ``cfg.out`` with config.json (config, the settings its defaults resolved to,
    versions, device, git commit, command) and
    metrics.csv's header of ``fields``; refuse a directory :func:`check_out` refuses."""
    check_out(cfg)
    try:
        os.makedirs(cfg.out, exist_ok=True)
        write_json(os.path.join(cfg.out, "config.json"), {
            "config": config_dict(cfg), "resolved": resolved_settings(cfg),
            "versions": package_versions(),
            "device": str(jax.devices()[0].device_kind), "git": git_state(),
            "command": command_line()})
        with open(os.path.join(cfg.out, "metrics.csv"), "w", newline="") as f:
            csv.writer(f).writerow(fields)
    except OSError as e:
        raise ConfigError(f"--out {cfg.out}: {e.strerror or e}") from None


def append_rows(out: str, rows: list[dict], fields: tuple[str, ...]) -> None:
    with open(os.path.join(out, "metrics.csv"), "a", newline="") as f:
        w = csv.DictWriter(f, fields)
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())


def _tuples(v):
    """JSON lists back to the config's (nested) tuples."""
    return tuple(_tuples(x) for x in v) if isinstance(v, list) else v


def read_run_config(run_dir: str) -> tuple[TrainConfig, dict]:
    """(the config a run saved in ``run_dir/config.json``, with ``out`` set to ``run_dir``;
    the whole saved JSON), or a :class:`ConfigError` naming what is wrong."""
    path = os.path.join(run_dir, "config.json")
    if not os.path.isfile(path):
        raise ConfigError(f"{path} does not exist: not a run directory (--out of a run)")
    try:
        with open(path) as f:
            saved = json.load(f)
        cfg = make({**{k: _tuples(v) for k, v in saved["config"].items()}, "out": run_dir},
                   drop_unset=True)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"{path} is not a flrjax run's config ({type(e).__name__}: {e})"
                          ) from None
    return cfg, saved
