"""What a run leaves in its directory: config.json with its provenance (versions, git commit,
command), metrics.csv, and for a person to look at its summary, ``curves.png`` and TensorBoard
events, from the trainer's metric rows.

Rows come as :func:`flrjax.runner.train` returns them: one per run (seed x sweep point) per
evaluation, run ``r`` being seed ``r % seeds`` of sweep point ``r // seeds``.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import shlex
import subprocess
import sys

import jax
import numpy as np

from flrjax.config import ConfigError, TrainConfig, algo_config

#: The paper's names of the methods (``--algo``).
METHOD_NAMES = {"flat": "flat TD3+HER", "dhrl": "DHRL", "flr_dhrl": "FLR+DHRL", "pig": "PIG",
                "flr_pig": "FLR+PIG", "higl": "HIGL"}

#: Panels of ``curves.png``: metric, y label, cumulative over evaluations.
CURVES = (("success_rate", "success rate (evaluation)", False),
          ("falls", "falls (cumulative, per seed)", True),
          ("critic_loss", "low-level critic loss", False))


#: How a swept field appears in a curve's name.
FIELD_LABELS = {"flr_alpha": "α", "flr_eps": "ε", "flr_next": "next",
                "initial_episodes": "initial episodes", "pig_jump_temp": "jump_temp"}


def method_name(algo: str, alpha: float | None = None) -> str:
    """The paper's name of a run's method: an FLR method at alpha = 0 is its base method
    (eq. 1's sparse reward)."""
    return METHOD_NAMES[algo.removeprefix("flr_") if alpha == 0 else algo]


def point_name(algo: str, point: dict) -> str:
    """A sweep point as the paper names it (:func:`method_name`; at alpha = 0 the FLR fields
    do not apply); other swept values follow."""
    base = point.get("flr_alpha") == 0
    name = method_name(algo, point.get("flr_alpha"))
    shown = [f"{FIELD_LABELS.get(k, k)}={v}" for k, v in point.items()
             if not (base and k.startswith("flr_"))]
    return " ".join([name, *shown])


def table(rows: list[dict], key: str, points: int, seeds: int) -> np.ndarray:
    """``[evaluations, points, seeds]`` of one metric."""
    return np.array([float(r[key]) for r in rows]).reshape(-1, points, seeds)


def _std(x: np.ndarray) -> np.ndarray:
    """Sample standard deviation over seeds (last axis; ddof 1), 0 for a single seed."""
    return x.std(-1, ddof=1) if x.shape[-1] > 1 else np.zeros(x.shape[:-1])


def summarize(algo: str, points: list[dict], seeds: int, steps: int, rows: list[dict],
              out: str | None) -> dict:
    """Per sweep point: success at the last evaluation (mean and sample std over seeds) and at
    the best one (its seed mean and the first step it was reached), falls in the last
    evaluation and in all of them (per seed, mean over seeds); the run's steps, wall time and
    files."""
    n = len(points)
    step = np.array([r["step"] for r in rows[::n * seeds]])
    success, falls = (table(rows, k, n, seeds) for k in ("success_rate", "falls"))
    best = success.mean(-1).argmax(0)
    summary = {
        "env_steps_per_seed": int(step[-1]), "of": steps, "seeds": seeds,
        "wall_time_s": float(rows[-1]["wall_time"]),
        "std": "sample standard deviation over seeds (ddof 1)",
        "points": [{
            "name": point_name(algo, pt), **pt,
            "success": {"mean": float(success[-1, i].mean()), "std": float(_std(success[-1, i]))},
            "best_success": {"mean": float(success[best[i], i].mean()),
                             "step": int(step[best[i]])},
            "falls_last_eval": float(falls[-1, i].mean()),
            "falls_total": float(falls[:, i].sum(0).mean()),
        } for i, pt in enumerate(points)],
    }
    if out:
        summary["files"] = {name: os.path.join(out, name) for name in sorted(os.listdir(out))}
    return summary


def format_summary(s: dict) -> str:
    """The summary as the lines a run prints at its end."""
    lines = [f"{s['env_steps_per_seed']:,} of {s['of']:,} env steps per seed, {s['seeds']} "
             f"seed(s), {s['wall_time_s'] / 60:.1f} min"]
    for p in s["points"]:
        lines.append(
            f"  {p['name']}: success {p['success']['mean']:.2f} ± {p['success']['std']:.2f} "
            f"(best {p['best_success']['mean']:.2f} at {p['best_success']['step']:,}); falls "
            f"{p['falls_last_eval']:.1f} in the last evaluation, {p['falls_total']:.0f} in all")
    lines.append("  (± is the sample std over seeds)")
    for name, path in s.get("files", {}).items():
        lines.append(f"  {name + ':':<14}{path}")
    return "\n".join(lines)


def plot_curves(algo: str, points: list[dict], seeds: int, rows: list[dict], path: str) -> None:
    """``curves.png``: success, cumulative falls and critic loss against env steps per seed,
    mean over seeds with a ± sample-std band (success's clipped to [0, 1]), one line per
    sweep point."""
    from matplotlib.figure import Figure  # no pyplot: works without a display

    n = len(points)
    step = np.array([r["step"] for r in rows[::n * seeds]])
    panels = [c for c in CURVES if c[0] in rows[0]]
    fig = Figure(figsize=(4.2 * len(panels), 3.4))
    for ax, (key, label, cumulative) in zip(fig.subplots(1, len(panels), squeeze=False)[0],
                                            panels, strict=True):
        t = table(rows, key, n, seeds)
        if cumulative:
            t = t.cumsum(0)
        for i, pt in enumerate(points):
            with np.errstate(all="ignore"):
                m, s = np.nanmean(t[:, i], -1), _std(t[:, i])
            lo, hi = m - s, m + s
            if key == "success_rate":
                lo, hi = np.clip(lo, 0, 1), np.clip(hi, 0, 1)
            ax.plot(step, m, label=point_name(algo, pt), color=f"C{i % 10}")
            ax.fill_between(step, lo, hi, alpha=0.2, color=f"C{i % 10}")
        ax.set_xlabel("env steps per seed")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.axes[0].legend(fontsize=8)
    fig.suptitle(f"{seeds} seed(s); band: ± sample std over seeds", fontsize=9)
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


def provenance() -> dict:
    """What a benchmark's result file records of its origin: the command line, and the
    commit (:func:`git_state`)."""
    return {"command": shlex.join(["python", *sys.argv]), **git_state()}


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
    """``cfg`` as config.json holds it (a sweep's tuples as lists), to compare with one."""
    d = json.loads(json.dumps(dataclasses.asdict(cfg)))
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
    with them (its flags leave them None): the updates' matrix operands, and for the methods
    that have them eq. 5's candidate values (operands, reaching transitions per evaluation,
    null for all at once, kernel) and subgoal testing's (operands, kernel)."""
    a = algo_config(cfg)
    base = getattr(a, "base", a)  # PIG and HIGL wrap the shared hierarchy
    td3 = base.td3 if hasattr(base, "td3") else base.low
    out = {"train_precision": td3.train_precision}
    flr = getattr(base, "flr", None)
    if flr is not None:
        out.update(flr_precision=flr.value_dtype, flr_value_chunk=flr.value_chunk,
                   flr_value_kernel=flr.value_kernel)
    if hasattr(base, "subgoal_test_precision"):
        out.update(subgoal_test_precision=base.subgoal_test_precision,
                   subgoal_test_kernel=base.subgoal_test_kernel)
    return out


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
            "command": shlex.join(sys.argv)})
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
