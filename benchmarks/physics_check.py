"""The physics choices of flrjax's ants, checked: how often 30 s of uniformly random torques
flip the ant (on its back), in C MuJoCo for several integrator/solver settings and in MJX for
the defaults, plus the torso heights that set the fall threshold. CPU only, a few minutes.

    python benchmarks/physics_check.py --out benchmarks/results/physics_check.json
"""

from __future__ import annotations

import argparse
import json
import sys

import jax
import mujoco
import numpy as np

from flrjax import envs

SETTINGS = {  # name -> AntSpec overrides
    "RK4, 100 iterations (reference-like)": dict(integrator="RK4", solver_iterations=100,
                                                 ls_iterations=50),
    "Euler, 100 iterations": dict(solver_iterations=100, ls_iterations=50),
    "Euler, 2 iterations (flrjax default)": dict(),
    "Euler, 1 iteration": dict(solver_iterations=1),
}


def c_mujoco(name: str, overrides: dict, episodes: int, steps: int) -> dict:
    """Flip rate and upright/flipped torso heights under random torques, in C MuJoCo."""
    env = envs.make(name, **overrides)
    m = env.mj_model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    flipped, z_up = [], []
    for _ in range(episodes):
        mujoco.mj_resetData(m, d)
        d.qpos[7:] += rng.uniform(-0.1, 0.1, size=m.nq - 7)
        d.qvel[:] = rng.normal(0, 0.1, size=m.nv)
        for _ in range(steps):
            d.ctrl[:] = rng.uniform(-1, 1, size=m.nu)
            mujoco.mj_step(m, d, env.config.frame_skip)
            up_z = 1 - 2 * (d.qpos[4] ** 2 + d.qpos[5] ** 2)
            if up_z > 0.5:
                z_up.append(d.qpos[2])
        flipped.append(1 - 2 * (d.qpos[4] ** 2 + d.qpos[5] ** 2) < 0)
    return {"flipped": float(np.mean(flipped)), "min_upright_z": float(np.min(z_up))}


def mjx(name: str, episodes: int, steps: int) -> dict:
    """Flip rate and final torso heights under random torques, in MJX (the env itself)."""
    env = envs.make(name)

    def roll(key):
        k1, k2 = jax.random.split(key)
        acts = jax.random.uniform(k2, (steps, env.action_size), minval=-1.0)
        s, _ = jax.lax.scan(lambda s, a: (env.step(s, a), None), env.reset(k1), acts)
        q = s.pipeline_state.qpos
        return 1 - 2 * (q[4] ** 2 + q[5] ** 2), q[2]

    up, z = jax.jit(jax.vmap(roll))(jax.random.split(jax.random.PRNGKey(0), episodes))
    up, z = np.asarray(up), np.asarray(z)
    return {"flipped": float(np.mean(up < 0)),
            "z_flipped_median": float(np.median(z[up < 0])) if (up < 0).any() else None}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=30)
    p.add_argument("--steps", type=int, default=300, help="env steps (0.1 s each)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    result = {"command": "python " + " ".join(sys.argv), "device": "cpu",
              "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__},
              "episodes": args.episodes, "steps": args.steps, "c_mujoco": {}, "mjx": {}}
    for name in ("ant4leg", "ant3leg"):
        for label, overrides in SETTINGS.items():
            r = c_mujoco(name, overrides, args.episodes, args.steps)
            result["c_mujoco"][f"{name}: {label}"] = r
            print(f"C MuJoCo {name:8s} {label:40s} flipped {r['flipped']:.2f}  "
                  f"min upright z {r['min_upright_z']:.3f}", flush=True)
        r = mjx(name, 16, args.steps)
        result["mjx"][name] = r
        print(f"MJX      {name:8s} {'flrjax default':40s} flipped {r['flipped']:.2f}  "
              f"median z when flipped {r['z_flipped_median']}", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
