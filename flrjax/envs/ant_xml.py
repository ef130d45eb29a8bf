"""MJCF builder: an ant with ``n`` legs in a maze whose walls are boxes.

Geometry, masses and joint limits follow the HIRO/DHRL ant
(jayLEE0301/dhrl_official ``envs/antenv/assets/ant.xml``): a sphere torso of radius 0.25, legs of
three capsules (radius 0.08; 0.2·√2, 0.2·√2 and 0.4·√2 long), hips about z in ±30°, ankles in
30°..70° (foot pointing down), density 5, joint damping 1 and armature 1, motors of ±30.

Changes for MJX speed (each keeps the behaviour the reference has):
- Walls: the maze's outer boundary is four half-spaces (planes: analytic, cheap contacts) and
  only the walls inside the free space's bounding box are boxes (one in the U-maze, none in the
  room); the boundary's boxes are still drawn, as visual-only geoms that never collide.
- Collisions: only the torso and the feet (lower-leg capsules) touch the floor, and by default
  only the torso touches the walls (``walls_collide_with``): that keeps the torso, whose x, y is
  the goal space, out of the walls at a quarter of the contacts, while a foot may reach into a
  wall. The reference's ant does not collide with itself either (``conaffinity=0`` on its
  geoms); hip and upper-leg capsules could only touch the floor once the ant lies on its back,
  when the torso sphere rests on the floor anyway.
- Integrator: semi-implicit Euler with ``timestep`` 0.02 and 5 substeps per env step (0.1 s,
  as the reference's RK4 with 0.02 and frame skip 5); RK4 costs 4 force evaluations per substep.
- Solver: Newton with few iterations (MJX unrolls nothing: every iteration is a device loop).
- Motors: ``gear=30, ctrlrange=±1`` instead of ``gear=1, ctrlrange=±30``: the same torques, with
  actions in [-1, 1] as brax envs take them.
- The goal marker body of the reference is dropped (it is only drawn).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from flrjax.envs.maze import Maze


@dataclasses.dataclass(frozen=True)
class AntSpec:
    """Body and simulation parameters of an n-legged ant."""

    n_legs: int = 4
    # Leg directions in degrees; None = evenly spaced starting at ``first_leg_deg``.
    first_leg_deg: float = 45.0
    torso_radius: float = 0.25
    torso_height: float = 0.75  # initial torso z: dhrl_official ant.xml body "torso" pos
    hip_len: float = 0.2 * math.sqrt(2)
    thigh_len: float = 0.2 * math.sqrt(2)
    foot_len: float = 0.4 * math.sqrt(2)
    leg_radius: float = 0.08
    density: float = 5.0
    gear: float = 30.0  # ctrlrange ±30 in dhrl_official ant.xml; action_max 30 in AntMaze.sh
    hip_range_deg: float = 30.0
    ankle_range_deg: tuple[float, float] = (30.0, 70.0)
    timestep: float = 0.02  # dhrl_official ant.xml <option timestep="0.02">
    integrator: str = "Euler"
    # Newton with 2 iterations: 1 flips the ant under random actions where the converged
    # solver does not (tests/envs/test_ant_maze.py checks it; docs/results.md).
    solver_iterations: int = 2
    ls_iterations: int = 4
    # Which ant geoms the walls stop: "torso" (default) or "torso_feet". Both keep the torso, and
    # so the goal-space position, out of the walls; "torso_feet" also keeps the feet out but
    # has 54 instead of 14 potential contacts in the U-maze and costs throughput at large
    # batch (docs/benchmarks.md).
    walls_collide_with: str = "torso"

    def leg_angles(self) -> list[float]:
        return [self.first_leg_deg + 360.0 * k / self.n_legs for k in range(self.n_legs)]


def _f(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in np.atleast_1d(v))


def _leg(k: int, angle_deg: float, spec: AntSpec, foot_contype: int) -> str:
    """One leg: hip segment, a hip joint about z, thigh, an ankle joint, foot."""
    a = math.radians(angle_deg)
    d = np.array([math.cos(a), math.sin(a), 0.0])
    # Ankle axis = z × d, so that positive angles push the foot down; with the reference's
    # range 30°..70° the foot points down for every leg (its four legs flip axis and range
    # together, which is the same joint).
    axis = np.array([-d[1], d[0], 0.0])
    hip_end, thigh_end, foot_end = d * spec.hip_len, d * spec.thigh_len, d * spec.foot_len
    lo, hi = spec.ankle_range_deg
    return f"""
      <body name="leg{k}" pos="0 0 0">
        <geom name="hip{k}_geom" type="capsule" fromto="0 0 0 {_f(hip_end)}"/>
        <body name="thigh{k}" pos="{_f(hip_end)}">
          <joint name="hip_{k}" type="hinge" axis="0 0 1"
                 range="{-spec.hip_range_deg} {spec.hip_range_deg}"/>
          <geom name="thigh{k}_geom" type="capsule" fromto="0 0 0 {_f(thigh_end)}"/>
          <body name="shin{k}" pos="{_f(thigh_end)}">
            <joint name="ankle_{k}" type="hinge" axis="{_f(axis)}" range="{lo} {hi}"/>
            <geom name="foot{k}_geom" type="capsule" fromto="0 0 0 {_f(foot_end)}"
                  contype="{foot_contype}" rgba="0.9 0.5 0.3 1"/>
          </body>
        </body>
      </body>"""


def ant_maze_xml(spec: AntSpec, maze: Maze) -> str:
    """The MJCF string of ``spec``'s ant at the maze's start, with the maze's walls.

    Collision bits: the floor and walls have ``contype=0 conaffinity=1``; the torso (and the
    feet) ``contype=1 conaffinity=0``; every other ant geom neither. So the ant touches floor and
    walls only through those geoms, never itself, and static geoms never pair up.
    """
    wall_contype = 1 if spec.walls_collide_with == "torso_feet" else 0
    if spec.walls_collide_with not in ("torso_feet", "torso"):
        raise ValueError(f"walls_collide_with must be 'torso_feet' or 'torso', "
                         f"got {spec.walls_collide_with!r}")
    # Feet always touch the floor; with walls_collide_with="torso" they use a second bit that
    # only the floor accepts.
    foot_contype = 1 if wall_contype else 2
    legs = "".join(_leg(k, ang, spec, foot_contype) for k, ang in enumerate(spec.leg_angles()))
    wall_h = maze.height * maze.scale / 2
    inner, outer = maze.split_wall_boxes()
    walls = "".join(
        f'\n    <geom name="wall{b}" type="box" pos="{_f(c)} {wall_h:.6g}" '
        f'size="{_f(h)} {wall_h:.6g}" contype="0" conaffinity="1" rgba="0.4 0.4 0.4 1"/>'
        for b, (c, h) in enumerate(inner)
    )
    walls += "".join(
        f'\n    <geom name="boundary{b}" type="plane" pos="{_f(p)} {wall_h:.6g}" '
        f'zaxis="{_f(n)} 0" size="{wall_h:.6g} {wall_h:.6g} 1" contype="0" conaffinity="1" '
        f'rgba="0 0 0 0"/>'
        for b, (p, n) in enumerate(maze.outer_walls())
    )
    walls += "".join(
        f'\n    <geom name="boundary_box{b}" type="box" pos="{_f(c)} {wall_h:.6g}" '
        f'size="{_f(h)} {wall_h:.6g}" contype="0" conaffinity="0" rgba="0.4 0.4 0.4 1"/>'
        for b, (c, h) in enumerate(outer)
    )
    lo, hi = maze.bounds
    floor_half = float(np.max(np.abs(np.concatenate([lo, hi])))) + maze.scale
    start = maze.start
    actuators = "".join(
        f'\n    <motor joint="{j}_{k}" gear="{spec.gear:g}" ctrlrange="-1 1" ctrllimited="true"/>'
        for k in range(spec.n_legs)
        for j in ("hip", "ankle")
    )
    return f"""<mujoco model="ant{spec.n_legs}leg_maze">
  <compiler angle="degree" inertiafromgeom="true"/>
  <option timestep="{spec.timestep:g}" integrator="{spec.integrator}"
          iterations="{spec.solver_iterations}" ls_iterations="{spec.ls_iterations}"/>
  <default>
    <joint limited="true" armature="1" damping="1"/>
    <geom condim="3" contype="0" conaffinity="0" margin="0.01" friction="1 0.5 0.5"
          solref=".02 1" solimp=".8 .8 .01" density="{spec.density:g}"
          size="{spec.leg_radius:g}" rgba="0.8 0.6 0.4 1"/>
  </default>
  <worldbody>
    <light directional="true" diffuse="0.8 0.8 0.8" pos="0 0 30" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="{floor_half:.6g} {floor_half:.6g} 1"
          contype="0" conaffinity="{1 | 2}" rgba="0.8 0.9 0.8 1"/>{walls}
    <body name="torso" pos="{_f(start)} {spec.torso_height:g}">
      <freejoint name="root"/>
      <geom name="torso_geom" type="sphere" size="{spec.torso_radius:g}" contype="1"/>{legs}
    </body>
  </worldbody>
  <actuator>{actuators}
  </actuator>
</mujoco>
"""
