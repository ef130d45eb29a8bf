"""Draw an environment: the maze from above (walls, start, goal, the goal-sampling area), and,
where MuJoCo can render offscreen (``MUJOCO_GL=egl`` or ``osmesa``), a frame of the ant.

    python -m flrjax.envs.show ant4leg --out ant4leg.png
"""

from __future__ import annotations

import argparse
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from flrjax import envs  # noqa: E402


def draw_maze(ax, env, name: str) -> None:
    """The maze from above in world coordinates."""
    maze = env.maze
    for c, h in maze.wall_boxes():
        ax.add_patch(Rectangle(c - h, *(2 * h), color="0.35"))
    for c in maze.free_cells:
        ax.add_patch(Rectangle(c - maze.scale / 2, maze.scale, maze.scale, color="#e8f2e8"))
    ax.add_patch(Circle(maze.goal, env.config.success_radius, fill=False, ls="--", color="C3",
                        label=f"success radius {env.config.success_radius:g}"))
    ax.plot(*maze.start, "o", color="C0", ms=10, label=f"start {tuple(maze.start.tolist())}")
    ax.plot(*maze.goal, "*", color="C3", ms=16, label=f"eval goal {tuple(maze.goal.tolist())}")
    lo, hi = maze.bounds
    ax.set_xlim(lo[0] - maze.scale, hi[0] + maze.scale)
    ax.set_ylim(lo[1] - maze.scale, hi[1] + maze.scale)
    ax.set_aspect("equal")
    ax.set_title(f"{name}: {hi[0] - lo[0]:g} x {hi[1] - lo[1]:g} free space")
    ax.legend(loc="upper right", fontsize=7)


def render_frame(env, width: int = 480, height: int = 360) -> np.ndarray | None:
    """An RGB frame of the ant after 1 s of settling from its start pose under zero action, or
    None when no offscreen GL is available."""
    import mujoco

    try:
        renderer = mujoco.Renderer(env.mj_model, height=height, width=width)
    except Exception as e:  # no EGL/OSMesa/GLFW context on this machine
        print(f"no MuJoCo frame ({type(e).__name__}: {e}); set MUJOCO_GL=egl or osmesa",
              file=sys.stderr)
        return None
    data = mujoco.MjData(env.mj_model)
    for _ in range(int(round(1.0 / env.mj_model.opt.timestep))):
        mujoco.mj_step(env.mj_model, data)
    cam = mujoco.MjvCamera()
    cam.lookat[:] = [0.0, 0.0, 0.3]
    cam.distance, cam.azimuth, cam.elevation = 4.0, 120.0, -25.0
    renderer.update_scene(data, camera=cam)
    frame = renderer.render()
    renderer.close()
    return frame


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description="Draw a flrjax environment to a PNG.")
    p.add_argument("name", choices=envs.names())
    p.add_argument("--out", required=True, help="PNG file to write")
    p.add_argument("--no-frame", action="store_true", help="skip the MuJoCo frame")
    args = p.parse_args(argv)
    env = envs.make(args.name)
    frame = None
    if hasattr(env, "mj_model") and not args.no_frame:
        frame = render_frame(env)
    ncols = 1 if frame is None else 2
    fig, axes = plt.subplots(1, ncols, figsize=(5 * ncols, 5), squeeze=False)
    draw_maze(axes[0, 0], env, args.name)
    if frame is not None:
        axes[0, 1].imshow(frame)
        axes[0, 1].set_axis_off()
        axes[0, 1].set_title(f"{env.spec.n_legs}-legged ant (MuJoCo)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
