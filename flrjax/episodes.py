"""Look at a policy: evaluation episodes of a run's newest checkpoint, drawn from above.

One panel per seed (rows) and sweep point or method (columns): the maze, start and goal, the
landmark graph (graph methods), the waypoints and subgoals the method chose, the torso's path
coloured by time and its falls. The episodes are those of the run's own evaluation after that
checkpoint's chunk (same policy, same keys), the ones its metrics.csv row scored.
Optionally a GIF of one episode through MuJoCo's renderer (the ant; needs an offscreen GL,
e.g. ``MUJOCO_GL=egl`` on a GPU machine).

    python -m flrjax.episodes RUN_DIR [--out FILE.png] [--episodes N] [--seeds 0,1]
                              [--video FILE.gif]
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import sys
import warnings
from collections.abc import Sequence

import matplotlib

matplotlib.use("Agg")
import jax  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from flrjax import algos, analysis, checkpoint, metrics_io, run_axis, runner  # noqa: E402
from flrjax.config import (  # noqa: E402
    ConfigError,
    TrainConfig,
    make_env,
    program_config,
    sweep_points,
)
from flrjax.envs.show import draw_maze  # noqa: E402
from flrjax.metric_names import columns  # noqa: E402
from flrjax.sweep import run_values  # noqa: E402

PROG = "python -m flrjax.episodes"


def load_config(run_dir: str) -> TrainConfig:
    """The config a run saved in ``run_dir/config.json`` (as ``--resume`` reads it)."""
    return metrics_io.read_run_config(run_dir)[0]


@functools.cache
def _traced_evaluate(cfg: TrainConfig):
    """Every run's ``evaluate(..., trace=True)``, vmapped and jitted as the trainer's
    evaluation is (each run with its swept values)."""
    env, algo = make_env(cfg), algos.get(cfg.algo)

    def one(carry, key, values):
        return algo.evaluate(carry, key, env, program_config(cfg, values or None, env),
                             trace=True)

    return jax.jit(lambda carry, keys: jax.vmap(one)(carry, keys, run_values(cfg)),
                   compiler_options=runner.compiler_options(cfg))


@dataclasses.dataclass(frozen=True)
class Episodes:
    """A checkpoint's traced evaluation: ``trace`` leaves ``[runs, n, T, ...]``
    (:func:`flrjax.algos.rollout.traced`), ``metrics`` ``[runs]`` by metrics.csv's columns
    (:func:`flrjax.metric_names.columns`), the landmark graph's
    ``landmarks [runs, K, 2]`` and ``edges`` (pairs of landmark ids per run) where the method
    has one."""

    cfg: TrainConfig
    chunks: int  # chunks done at the checkpoint
    trace: dict
    metrics: dict
    landmarks: list[np.ndarray] | None
    edges: list[np.ndarray] | None

    @property
    def step(self) -> int:
        return self.chunks * self.cfg.steps_per_chunk


def trace_run(run_dir: str, episodes: int | None = None) -> Episodes:
    """The newest readable checkpoint of ``run_dir`` evaluated with a trace: the evaluation
    the run made after that chunk, or, with ``episodes`` other than the run's
    ``eval_episodes``, that many episodes to the maze's goal with the same keys. On one
    device: the checkpoint's runs are read without their padding."""
    cfg = dataclasses.replace(load_config(run_dir), devices=1)
    if not checkpoint.has_checkpoint(run_dir):
        raise ConfigError(f"no checkpoint in {checkpoint.ckpt_dir(run_dir)} (run with "
                          "--checkpoint-every, the default, to keep one)")
    if episodes is not None and episodes < 1:
        raise ConfigError(f"--episodes must be at least 1, got {episodes}")
    init, _, _ = runner.build(cfg)
    key = jax.random.PRNGKey(cfg.seed)
    chunks, carry = checkpoint.load(run_dir, runner.carry_shapes(cfg, init))
    keys = run_axis.run_keys(cfg, jax.random.fold_in(jax.random.fold_in(key, 1), chunks - 1))
    ecfg = cfg if episodes is None else dataclasses.replace(cfg, eval_episodes=episodes)
    metrics, trace = jax.tree.map(np.asarray, _traced_evaluate(ecfg)(carry, keys))
    landmarks = edges = None
    if hasattr(carry, "graph"):
        g = jax.tree.map(np.asarray, carry.graph)
        mask = g.landmarks.mask
        landmarks = [g.landmarks.goal[r][mask[r]] for r in range(cfg.runs)]
        edges = [_edges(g.weight[r][np.ix_(mask[r], mask[r])]) for r in range(cfg.runs)]
    return Episodes(cfg, chunks, trace, columns(metrics), landmarks, edges)


def _edges(weight: np.ndarray) -> np.ndarray:
    """Pairs ``[E, 2]`` of landmarks joined by an edge either way (finite weight), once each."""
    linked = np.isfinite(weight) | np.isfinite(weight.T)
    return np.argwhere(np.triu(linked, k=1))


def _fall_steps(fallen: np.ndarray, final_fallen: bool) -> np.ndarray:
    """The step (of the path with its final state, ``T + 1``) where the body first falls over,
    or none: a body on its side can cross the fallen height back and forth, so only the first
    fall of an episode is marked."""
    return np.flatnonzero(np.append(fallen, final_fallen))[:1]


def draw(ep: Episodes, seeds: Sequence[int] | None = None) -> plt.Figure:
    """The figure: one panel per run (rows: ``seeds``, default all; columns: sweep points),
    see the module."""
    cfg, env = ep.cfg, make_env(ep.cfg)
    seeds = list(range(cfg.seeds)) if seeds is None else list(seeds)
    points = sweep_points(cfg)
    horizon = env.config.episode_length
    norm, cmap = plt.Normalize(0, horizon), plt.get_cmap("viridis")
    fig, axes = plt.subplots(len(seeds), len(points), squeeze=False, layout="constrained",
                             figsize=(4.0 * len(points) + 1.4, 3.4 * len(seeds) + 1.2))
    env_name = analysis.env_name(cfg.env)
    unit = "m" if hasattr(env, "mj_model") else "world units"
    goal = np.asarray(env.maze.goal)
    drawn: set[str] = set()
    for p, point in enumerate(points):
        for row, s in enumerate(seeds):
            r, ax = p * cfg.seeds + s, axes[row, p]
            draw_maze(ax, env, env_name)
            ax.get_legend().remove()
            lo, hi = env.maze.bounds  # the free space and a margin of wall, not the whole scale
            ax.set_xlim(lo[0] - 1, hi[0] + 1)
            ax.set_ylim(lo[1] - 1, hi[1] + 1)
            if ep.landmarks is not None and len(ep.landmarks[r]):
                lm = ep.landmarks[r]
                ax.add_collection(LineCollection(lm[ep.edges[r]], colors="C0", lw=0.5,
                                                 alpha=0.4, zorder=2))
                ax.plot(*lm.T, "o", color="C0", ms=1.5, alpha=0.6, zorder=3)
                drawn.add("graph")
            tr = {k: v[r] for k, v in ep.trace.items()}
            for kind, marker, colour, size in [("subgoal", "^", "C4", 6),
                                               ("waypoint", "D", "C1", 3)]:
                xy = np.unique(tr[kind].reshape(-1, 2), axis=0)
                xy = xy[np.linalg.norm(xy - goal, axis=-1) > 1e-6]  # not the final goal
                ax.plot(*xy.T, marker, color=colour, ms=size, alpha=0.6, ls="", zorder=4)
                drawn.update([kind] if len(xy) else [])
            falls = 0
            for e in range(tr["xy"].shape[0]):
                path = np.concatenate([tr["xy"][e], tr["final_xy"][e][None]])
                seg = LineCollection(np.stack([path[:-1], path[1:]], 1), cmap=cmap, norm=norm,
                                     lw=1.4, zorder=5)
                seg.set_array(np.arange(horizon))
                ax.add_collection(seg)
                fell = _fall_steps(tr["fallen"][e], tr["final_fallen"][e])
                ax.plot(*path[fell].T, "x", color="red", ms=7, mew=2, ls="", zorder=6)
                falls += bool(len(fell))
            n, ok = tr["success"].shape[0], int(tr["success"].sum())
            fell_text = f", {falls}/{n} fall over" if analysis.can_fall(cfg.env) else ""
            ax.set_title(f"{analysis.point_name(cfg.algo, point)}, seed {s}:\n"
                         f"{ok}/{n} reach the goal{fell_text}", fontsize=9)
            if row == len(seeds) - 1:
                ax.set_xlabel(f"x ({unit})")
            if p == 0:
                ax.set_ylabel(f"y ({unit})")
    handles = [Patch(color="0.35", label="wall"),
               Line2D([], [], marker="o", color="C0", ls="", ms=8, label="start"),
               Line2D([], [], marker="*", color="C3", ls="", ms=12, label="goal"),
               Line2D([], [], color="C3", ls="--", label="success radius")]
    legend = {"graph": Line2D([], [], marker="o", color="C0", lw=0.6, ms=3,
                              label="landmark graph"),
              "subgoal": Line2D([], [], marker="^", color="C4", ls="",
                                label="subgoal (high level)"),
              "waypoint": Line2D([], [], marker="D", color="C1", ls="", ms=4,
                                 label="waypoint chased (low level)")}
    handles += [h for kind, h in legend.items() if kind in drawn]
    if analysis.can_fall(cfg.env):
        handles.append(Line2D([], [], marker="x", color="red", mew=2, ls="",
                              label="first fall of an episode"))
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 5),
               fontsize=8, frameon=False)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes, shrink=0.8,
                 label="env step of the episode")
    n = analysis.plural(ep.trace["success"].shape[1], "evaluation episode")
    fig.suptitle(f"{env_name}: {n} per panel, policy at env step {ep.step:,}")
    return fig


def write_gif(ep: Episodes, path: str, run: int = 0, episode: int = 0, every: int = 4,
              size: tuple[int, int] = (480, 360)) -> bool:
    """A GIF of one traced episode through MuJoCo's renderer, every ``every``-th step, the
    camera following the torso. False (with a one-line note) where the env has no MuJoCo
    body or no offscreen GL is available."""
    import mujoco
    from PIL import Image

    env = make_env(ep.cfg)
    qpos = ep.trace.get("qpos")
    if qpos is None or not hasattr(env, "mj_model"):
        print(f"{PROG}: no video: {ep.cfg.env} has no MuJoCo body to render", file=sys.stderr)
        return False
    try:
        with warnings.catch_warnings():  # GLFW's own warnings before its error, without X
            warnings.simplefilter("ignore")
            renderer = mujoco.Renderer(env.mj_model, height=size[1], width=size[0])
    except Exception as e:  # no EGL/OSMesa/GLFW context on this machine
        print(f"{PROG}: no video ({type(e).__name__}: {e}); set MUJOCO_GL=egl or osmesa",
              file=sys.stderr)
        return False
    data, cam = mujoco.MjData(env.mj_model), mujoco.MjvCamera()
    cam.distance, cam.azimuth, cam.elevation = 8.0, 90.0, -45.0
    frames = []
    for q in qpos[run, episode, ::every]:
        data.qpos[:] = q
        mujoco.mj_forward(env.mj_model, data)
        cam.lookat[:] = [q[0], q[1], 0.3]
        renderer.update_scene(data, camera=cam)
        frames.append(Image.fromarray(renderer.render()))
    renderer.close()
    dt = env.mj_model.opt.timestep * env.config.frame_skip * every
    frames[0].save(path, save_all=True, append_images=frames[1:], loop=0,
                   duration=max(20, int(1000 * dt)))
    return True


def _seeds(text: str) -> list[int]:
    """``--seeds 0,2`` as a list of seed indices."""
    try:
        seeds = [int(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seed indices like 0,2, got {text!r}"
                                         ) from None
    if min(seeds) < 0 or len(set(seeds)) < len(seeds):
        raise argparse.ArgumentTypeError(f"expected distinct seed indices >= 0, got {text!r}")
    return seeds


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    """A warning (e.g. an unreadable newest checkpoint, restored from an older one) as one
    line, in place of Python's file, line and source line."""
    return f"{PROG}: warning: {' '.join(str(message).split())}\n"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog=PROG, description=(
        "Draw the evaluation episodes of a run's newest checkpoint from above: one panel per "
        "seed (rows) and sweep point or method (columns)."))
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run's --out directory")
    p.add_argument("--out", metavar="FILE.png", help="the picture (default RUN_DIR/episodes.png)")
    p.add_argument("--episodes", type=int, metavar="N",
                   help="episodes per panel (default: the run's --eval-episodes, its own "
                        "evaluation)")
    p.add_argument("--seeds", type=_seeds, metavar="0,1",
                   help="the seeds to draw, one row each (default: all the run's seeds)")
    p.add_argument("--video", metavar="FILE.gif",
                   help="also a GIF of the first drawn seed's first episode (ant; needs an "
                        "offscreen GL, e.g. MUJOCO_GL=egl)")
    args = p.parse_args(argv)
    warnings.formatwarning = _one_line_warning
    if not os.path.isdir(args.run_dir):
        p.error(f"{args.run_dir} is not a directory")
    out = args.out or os.path.join(args.run_dir, "episodes.png")
    for path in (out, args.video):
        if path and not os.path.isdir(os.path.dirname(os.path.abspath(path))):
            p.error(f"cannot write {path}: its directory does not exist")
    try:
        n = load_config(args.run_dir).seeds
        seeds = args.seeds or list(range(n))
        if max(seeds) >= n:
            raise ConfigError(f"--seeds {max(seeds)}: the run has {analysis.plural(n, 'seed')}"
                              f" (0 to {n - 1})")
        ep = trace_run(args.run_dir, args.episodes)
    except ConfigError as e:
        p.exit(2, f"{PROG}: error: {e}\n")
    fig = draw(ep, seeds)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    print(f"wrote {out}")
    if args.video and write_gif(ep, args.video, run=seeds[0]):
        print(f"wrote {args.video}")


if __name__ == "__main__":
    main()
